"""Physics: refrigerant properties, components, the cycle, the simulation driver."""

import functools
import hashlib
from pathlib import Path


@functools.cache
def source_digest() -> str:
    """Digest of every Python source file of the physics package (hex): what its cached
    machine code was compiled from."""
    digest = hashlib.blake2b(digest_size=16)
    for path in sorted(Path(__file__).parent.rglob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()
