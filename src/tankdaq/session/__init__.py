"""The guided session (``tankdaq session``): a test plan walked condition by condition, with the operator."""
