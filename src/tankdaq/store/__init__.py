"""tankdaq.store"""
