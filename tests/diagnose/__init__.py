"""Tests of tankdaq's diagnose room."""
