"""tankdaq.acquire"""
