"""A run's results: metrics over the master's table, the CSV, summary.json, plots, videos and the results folder."""
