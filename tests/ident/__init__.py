"""Tests of tankdaq's ident room."""
