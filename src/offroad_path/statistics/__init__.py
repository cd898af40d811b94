"""Statistics below evaluation and driving, which both use them: scores from pixel counts (`scores`),
the hierarchical bootstrap over test worlds, blocks and seeds (`bootstrap`), exact tests and power of
intervention counts (`counts`), and the declared primaries with Holm's correction (`primaries`)."""
