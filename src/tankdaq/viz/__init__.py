"""tankdaq.viz"""
