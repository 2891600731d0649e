#!/usr/bin/python3
"""Predicted parallel efficiency of equal against balanced slabs per rank count (thesis Fig. 4.9
style), from one `sphmodel predict --decomposition equal,balanced` prediction.

    scripts/plot-balance.py PREDICTION.json OUT.png
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main():
    if len(sys.argv) != 3 or sys.argv[1] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr)
        sys.exit(0 if len(sys.argv) > 1 and sys.argv[1] in ("-h", "--help") else 2)
    try:
        p = json.load(open(sys.argv[1]))
        configs = p["configurations"]
    except (OSError, ValueError, KeyError) as e:
        print(f"plot-balance.py: '{sys.argv[1]}' is not a prediction ({e})", file=sys.stderr)
        sys.exit(2)
    q = p["request"]
    fig, ax = plt.subplots(figsize=(6, 4))
    for dec, style in (("equal", "o-"), ("balanced", "s-")):
        pts = [(c["ranks"], c["efficiency"]) for c in configs if c.get("decomposition", "equal") == dec]
        if pts:
            ax.plot([r for r, _ in pts], [e for _, e in pts], style, label=f"{dec} slabs")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("ranks (1 thread each)")
    ax.set_ylabel("parallel efficiency (predicted)")
    ax.set_ylim(0, 1.05)
    ax.set_title(f"{q['setup']} scale {q['scale']:g}, grid {q['grid']}, {q['steps']} steps, "
                 f"{q['cores']} cores", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=120)
    print(f"written {sys.argv[2]}")


if __name__ == "__main__":
    main()
