"""Shared helpers of the benchmark scripts: scans, timing, Markdown tables, BENCHMARKS.md."""

from __future__ import annotations

import os
import platform
import re
import statistics
import time
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

import asrbf_mesh as am

ROOT = Path(__file__).resolve().parents[1]
# The Stanford bunny range scans (bun000.ply, bun045.ply, bun090.ply, bun180.ply) are read
# from the folder named by $ASRBF_BUNNY_DIR; without it the benchmarks use the face map only.
BUNNY_DIR = Path(os.environ.get("ASRBF_BUNNY_DIR") or "$ASRBF_BUNNY_DIR-is-not-set")
BUNNIES = ("bun000", "bun045", "bun090", "bun180")


def scans(names: Iterable[str] | None = None) -> dict[str, am.Scan]:
    """The face map and, when present, the Stanford bunny scans.

    A name with a suffix (``views/syn270.ply``) is a scan file, read as it is and keyed by
    that name (:func:`label` gives its stem).
    """
    out: dict[str, am.Scan] = {}
    for name in names or ("face", *BUNNIES):
        if Path(name).suffix:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out[name] = am.load_scan(name)
            continue
        if name == "face":
            out[name] = am.load_scan(am.face_map_path())
            continue
        path = BUNNY_DIR / f"{name}.ply"
        if path.exists():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out[name] = am.load_scan(path)
        else:
            print(f"(skipping {name}: {path} not found)")
    return out


def label(name: str) -> str:
    """A scan's name in tables: a file's stem, else the name."""
    return Path(name).stem if Path(name).suffix else name


def timed(fn: Callable, *args, **kw):
    """Run ``fn`` and return (result, seconds)."""
    t0 = time.perf_counter()
    res = fn(*args, **kw)
    return res, time.perf_counter() - t0


def median_run(runs: list[dict], key: str = "ebar") -> dict:
    """The run whose ``key`` is the median (odd counts) or the lower median."""
    order = sorted(range(len(runs)), key=lambda i: runs[i][key])
    return runs[order[(len(runs) - 1) // 2]]


def median_worst(values: list[float], fmt: str, worst: Callable = max) -> str:
    """A table cell: the median of ``values`` and, in brackets, the worst of them.

    Counts (integers) take the lower median of an even number of values: a value one
    of the runs had, not a half neuron.
    """
    counts = all(isinstance(v, (int, np.integer)) for v in values)
    mid = statistics.median_low(values) if counts else statistics.median(values)
    return f"{format(mid, fmt)} ({format(worst(values), fmt)})"


def table(headers: list[str], rows: list[list]) -> str:
    """A Markdown table."""
    def fmt(v):
        if isinstance(v, float):
            if v == 0 or 1e-3 <= abs(v) < 1e5:
                return f"{v:.4g}" if abs(v) < 1 else f"{v:,.2f}"
            return f"{v:.3g}"
        if isinstance(v, (int, np.integer)):
            return f"{v:,}"
        return str(v)

    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(fmt(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)


def machine() -> str:
    """One line describing the machine."""
    import numba

    return (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"numpy {np.__version__}, numba {numba.__version__}, asrbf-mesh {am.__version__}")


def write_section(name: str, body: str, path: Path = ROOT / "BENCHMARKS.md") -> None:
    """Replace (or append) the section between ``<!-- name:start -->`` and ``<!-- name:end -->``."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{start}\n{body.rstrip()}\n{end}"
    text = path.read_text() if path.exists() else (
        "# Benchmarks\n\nEvery figure here is measured by a script in `scripts/`; the command "
        "that reproduces it heads its section.\n")
    if start in text and end in text:
        text = re.sub(re.escape(start) + r".*?" + re.escape(end), lambda _: block, text,
                      flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def subsample(scan: am.Scan, n: int, seed: int = 0) -> np.ndarray:
    """``n`` points of ``scan`` drawn at random without replacement, (n, 3)."""
    rng = np.random.default_rng(seed)
    return scan.points[np.sort(rng.choice(scan.n_points, n, replace=False))]


def best_time(fn: Callable, *args, repeat: int = 3, **kw) -> float:
    """Fastest of ``repeat`` timed calls of ``fn`` (seconds), after one untimed call."""
    fn(*args, **kw)
    return min(timed(fn, *args, **kw)[1] for _ in range(repeat))


def save_png(fig, path: Path, dpi: int = 110) -> None:
    """Save a matplotlib figure as PNG through a temporary file, then close it."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    tmp.replace(path)
    plt.close(fig)
