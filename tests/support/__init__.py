"""Helpers the tests share (data makers, a throwaway PostgreSQL server, the docs examples' runner);
imported as ``support.<module>``: pytest puts tests/ on sys.path for tests/conftest.py."""
