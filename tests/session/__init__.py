"""Tests of tankdaq's session room."""
