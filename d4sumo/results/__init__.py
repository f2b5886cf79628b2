"""Results: the paper's tables and clusters from stored samples, figures, the HTML report and the
comparison with the paper."""
