"""The evaluation protocol (docs/DESIGN.md §7): the independent style evaluator, the metrics, the
protocol's curves, per-clip metrics, D's probe, the driver and the reports.
"""
