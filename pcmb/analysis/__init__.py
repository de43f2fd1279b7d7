"""What is made of results: statistics for figures, comparisons, reports."""
