"""Tests of tankdaq's campaign room."""
