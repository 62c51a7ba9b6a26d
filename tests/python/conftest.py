import sys
from pathlib import Path

# Make tests/python/reference.py importable as `reference`.
sys.path.insert(0, str(Path(__file__).parent))
