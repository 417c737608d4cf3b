"""Campaigns: many recordings fitted per condition, in parallel, into tables and reports."""
