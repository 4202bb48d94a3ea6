"""Benchmarks of modular-robots: ``make bench`` (see ``__main__``)."""
