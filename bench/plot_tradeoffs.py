"""Time-against-error plots of docs/benchmarks.md (run in .venv-peers, which has matplotlib).

    .venv-peers/bin/python bench/plot_tradeoffs.py SPEC.json OUT.png

SPEC: {"title", "xlabel", "ylabel", "logx", "logy", "series": [{"name", "x": [...], "y": [...],
"labels": [...], "line": bool}]}; one marker/colour per series, each point labelled.
"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(spec_path, out):
    s = json.load(open(spec_path))
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    markers = "osD^v<>ph*"
    for i, se in enumerate(s["series"]):
        kw = dict(marker=markers[i % len(markers)], label=se["name"], linestyle="-" if se.get("line", True) else "none")
        ax.plot(se["x"], se["y"], **kw)
        for x, y, lab in zip(se["x"], se["y"], se.get("labels", [])):
            if lab:
                ax.annotate(lab, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
    if s.get("logx"):
        ax.set_xscale("log")
    if s.get("logy"):
        ax.set_yscale("log")
    ax.set_xlabel(s["xlabel"])
    ax.set_ylabel(s["ylabel"])
    ax.set_title(s["title"], fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
