"""Tests of the project as a whole: the docs' examples, the wheel, the architecture, make."""
