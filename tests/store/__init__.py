"""Tests of tankdaq's store room."""
