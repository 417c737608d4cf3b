"""Tests of tankdaq's xsens room."""
