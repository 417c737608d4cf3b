"""Tests of tankdaq's auv room."""
