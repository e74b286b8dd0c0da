"""Benchmarks over the whole pipeline: ``bench`` (the report's Figure 3 table), ``chart`` (speed against
accuracy, Pareto fronts)."""
