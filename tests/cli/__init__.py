"""Tests of tankdaq's cli room."""
