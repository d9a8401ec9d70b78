"""The course's benchmarks: each prints a ratio against a baseline measured in the same run, and
``tests/test_benchmark_guards.py`` guards each headline figure against its own past. The repository's
root is on the venv's path, so children import their targets as ``benchmarks.<module>:<name>``."""
