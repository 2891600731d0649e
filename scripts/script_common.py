"""What the measurement scripts share: the git commit, an atomic JSON write, reading a report of
one kind, and matplotlib's pyplot (Agg)."""
import json
import os
import subprocess
import sys


def git_commit(root):
    """The commit of the checkout at root (every report carries it); empty outside git."""
    return subprocess.run(["git", "-C", root, "rev-parse", "HEAD"], capture_output=True,
                          text=True).stdout.strip()


class InputError(Exception):
    """Bad input: one line naming it, exit 2, no file written."""


def load_report(path, benchmark, kind):
    """The JSON report at path, which must be a `benchmark` report (`kind` names it in the error,
    "an sph report"); InputError naming the file otherwise."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror}")
    except json.JSONDecodeError as e:
        raise InputError(f"{path} is not JSON ({e.msg} at line {e.lineno})")
    if not isinstance(doc, dict) or doc.get("benchmark") != benchmark:
        found = doc.get("benchmark") if isinstance(doc, dict) else None
        raise InputError(f"{path} is not {kind} (benchmark '{found}', expected '{benchmark}')")
    return doc


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
