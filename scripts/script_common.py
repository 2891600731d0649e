"""What the measurement scripts share: an atomic JSON write and matplotlib's pyplot (Agg)."""
import json
import os
import sys


def write_json(path, doc):
    """Write doc to path through a temporary file and a rename: never a partial report."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path + ".tmp", "w") as f:
        json.dump(doc, f, indent=2)
    os.replace(path + ".tmp", path)
    print(f"written {path}")


def pyplot(tool):
    """matplotlib.pyplot with the Agg backend, or None (and a one-line note) without it."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        return plt
    except ImportError:
        print(f"{tool}: no matplotlib (python3-matplotlib; run with /usr/bin/python3), no PNG",
              file=sys.stderr)
        return None
