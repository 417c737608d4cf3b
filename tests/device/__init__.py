"""Tests of tankdaq's device room."""
