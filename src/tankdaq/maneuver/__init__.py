"""tankdaq.maneuver"""
