"""Paper figures, sweeps and benchmarks; each writes PNG figures and a JSON of numbers."""
