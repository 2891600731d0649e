"""What the measurement scripts share: the git commit, an atomic JSON write and matplotlib's
pyplot (Agg)."""
import json
import os
import subprocess
import sys


def git_commit(root):
    """The commit of the checkout at root (every report carries it); empty outside git."""
    return subprocess.run(["git", "-C", root, "rev-parse", "HEAD"], capture_output=True,
                          text=True).stdout.strip()


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
