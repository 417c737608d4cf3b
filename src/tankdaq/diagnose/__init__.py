"""tankdaq.diagnose"""
