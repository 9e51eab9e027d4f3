"""The execution layer: the compiled stepping kernel and the plan compiled into its tables."""
