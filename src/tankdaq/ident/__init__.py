"""tankdaq.ident"""
