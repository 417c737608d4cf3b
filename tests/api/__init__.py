"""Tests of tankdaq's api room."""
