"""Markdown of the committed run's results: the tables' one renderer (rendering), their rows and
titles (tables), and the README's and docs/results.md's generated blocks (summary, readme)."""
