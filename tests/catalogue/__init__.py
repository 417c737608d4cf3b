"""Tests of tankdaq's catalogue room."""
