"""tankdaq.xsens"""
