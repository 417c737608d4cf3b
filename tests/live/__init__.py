"""Tests of tankdaq's live room."""
