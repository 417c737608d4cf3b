"""Tests of tankdaq's report room."""
