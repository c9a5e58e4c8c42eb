"""Benchmarks run through ``mbplan bench …``; each writes JSON, markdown and a plot."""
