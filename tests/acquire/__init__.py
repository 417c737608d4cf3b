"""Tests of tankdaq's acquire room."""
