"""What a person reads: summary tables, plots, JSON reports."""
