"""Configuration: hull files, test plans, their rules, and one check per command-line value."""
