"""tankdaq.auv"""
