"""Tests of tankdaq's physics room."""
