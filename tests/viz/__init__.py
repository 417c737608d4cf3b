"""Tests of tankdaq's viz room."""
