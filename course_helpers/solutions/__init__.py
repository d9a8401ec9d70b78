"""Reference solutions of the exercises, one module per chapter (used by instructors' CI)."""
