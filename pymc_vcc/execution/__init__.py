"""Execution: executors, worker pool, outcomes, checkpoints, progress."""
