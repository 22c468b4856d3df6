"""shspec's benchmarks: each ``bench_*.py`` (and ``wigner_accuracy.py``) measures shspec beside its peer in one
process; ``python -m benchmarks`` lists and runs them (:mod:`benchmarks.__main__`)."""
