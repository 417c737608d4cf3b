"""tankdaq.device"""
