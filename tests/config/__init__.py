"""Tests of tankdaq's config room."""
