"""Benchmarks behind ``pymc-vcc bench``.

Each module here exposes ``run(quick: bool) -> dict[str, float | int | str]``; the command runs
them in the order of :data:`BENCHMARKS` and merges their results into one JSON object.
"""

BENCHMARKS: tuple[str, ...] = ("properties", "sampler", "simulator", "smc")
