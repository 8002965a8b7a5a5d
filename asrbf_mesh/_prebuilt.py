"""Prebuilt kernels: numba's cache files compiled ahead of time, shipped with the package.

The first command on a machine would otherwise compile its numba kernels (12-15 s for a
fit of the face map, most of it numba's own work on the learning kernel, which no
scheduling can hide: compilation holds a process-wide lock and a fit needs nearly every
kernel). ``scripts/build_kernels.py`` compiles them once per x86-64 micro-architecture
level (``x86-64-v4``: AVX-512; ``x86-64-v3``: AVX2 and FMA) and stores numba's cache files
in ``asrbf_mesh/_prebuilt/``, with a manifest naming the sources (:func:`_jit_cache.source_key`),
the Python and numba versions and the target of each set.

On the first import on a machine, :func:`install` unpacks the best set the processor runs
(every feature of the level present) into the per-user kernel cache, and every process
that imports the package there has numba generate code for that level
(``numba.core.config.CPU_NAME`` and :data:`FEATURES`), so numba finds the shipped kernels
under its own keys and any kernel it compiles itself is code of the same level: one
code path never differs in the last bits from another (the ``fastmath`` reductions
vectorize at the level's width). Numba's settings are process-wide: other numba code in
the process gets level code too. When the manifest does not match (another source
version, Python, numba or platform), the processor has no level built, numba already
generated code in the process or ``NUMBA_CPU_NAME`` names another target, nothing changes
and numba compiles for this machine as before; a kernel file numba wrote here itself is
never replaced. ``ASRBF_NO_PREBUILT=1`` turns it off.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tarfile
import tempfile
from pathlib import Path

__all__ = ["ARCHIVES", "FEATURES", "LEVELS", "MARKER", "archives", "install", "level_features",
           "pack", "python_tag"]

#: Where the sets and their manifest live (``manifest.json``, ``<level>.tar.xz``);
#: ``$ASRBF_PREBUILT_DIR`` names another directory.
ARCHIVES = Path(__file__).resolve().parent / "_prebuilt"

#: The file in a kernel cache directory that records what :func:`install` did there.
MARKER = ".prebuilt"

_V2 = {"cx16", "popcnt", "sse3", "sse4.1", "sse4.2", "ssse3", "sahf"}
_V3 = _V2 | {"avx", "avx2", "bmi", "bmi2", "f16c", "fma", "lzcnt", "movbe", "xsave"}
_V4 = _V3 | {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}

#: The micro-architecture levels built, best first, and the processor features each needs
#: (the x86-64 psABI levels, in LLVM's feature names).
LEVELS: dict[str, frozenset[str]] = {"x86-64-v4": frozenset(_V4), "x86-64-v3": frozenset(_V3)}

#: The code generator's features for each level (``NUMBA_CPU_FEATURES``). At ``x86-64-v4``
#: LLVM prefers 256-bit vectors by default; the evaluation is 7 % faster with 512-bit ones
#: on the benchmark machine (56.0 against 60.0 ms for a million points, one thread, as fast
#: as code compiled for the machine itself).
FEATURES: dict[str, str] = {"x86-64-v4": "-prefer-256-bit", "x86-64-v3": ""}


def archives() -> Path:
    """Return the directory of the prebuilt sets (:data:`ARCHIVES` or ``$ASRBF_PREBUILT_DIR``)."""
    env = os.environ.get("ASRBF_PREBUILT_DIR")
    return Path(env) if env else ARCHIVES


def pack(kernels: Path, dest: Path, level: str, source_key: str) -> Path:
    """Pack the kernel cache directory ``kernels`` as ``level``'s set in ``dest``.

    The manifest there gains (or replaces) ``level`` and is rewritten for this Python,
    numba and platform; a manifest of other sources starts over. Returns the archive.
    """
    import llvmlite.binding as ll
    import numba

    dest.mkdir(parents=True, exist_ok=True)
    archive = dest / f"{level}.tar.xz"
    with tarfile.open(archive, "w:xz") as tar:
        for path in sorted(kernels.rglob("*")):
            if path.is_file() and path.suffix in (".nbi", ".nbc"):
                tar.add(path, arcname=str(path.relative_to(kernels)))
    path = dest / "manifest.json"
    manifest = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    levels = manifest.get("levels", {}) if manifest.get("source_key") == source_key else {}
    levels[level] = archive.name
    manifest = {"source_key": source_key, "numba": numba.__version__, "python": python_tag(),
                "triple": ll.get_process_triple(), "levels": levels}
    path.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    return archive


def python_tag() -> str:
    """Return the tag numba puts in its cache file names (``py311`` for CPython 3.11)."""
    return f"py{sys.version_info.major}{sys.version_info.minor}"


def level_features() -> set[str]:
    """Return the features of this machine's processor (LLVM's names, enabled only)."""
    import llvmlite.binding as ll

    flat = ll.get_host_cpu_features().flatten()
    return {f[1:] for f in flat.split(",") if f.startswith("+")}


def _target(level: str) -> bool:
    """Have numba generate code for ``level`` in this process; False if it cannot now."""
    from numba.core import config
    from numba.core.registry import cpu_target

    if config.CPU_NAME is not None or "_toplevel_target_context" in vars(cpu_target):
        # the user chose a target, or numba made its code generator already
        return config.CPU_NAME == level and config.CPU_FEATURES == FEATURES[level]
    config.CPU_NAME, config.CPU_FEATURES = level, FEATURES[level]
    return True


def install(cache: Path, source_key: str) -> str | None:
    """Use the best prebuilt set this machine runs, unpacked into ``cache``; its level or None.

    The set is judged and unpacked once per cache directory and manifest (:data:`MARKER`
    records the level, or ``none``, and the manifest's hash); every process then targets
    that level (:func:`_target`). Every failure leaves numba to compile for this machine.
    """
    marker = cache / MARKER
    if os.environ.get("ASRBF_NO_PREBUILT"):
        return None
    try:
        text = (archives() / "manifest.json").read_text(encoding="utf-8")
    except OSError:
        return None
    seen = hashlib.sha256(text.encode()).hexdigest()[:16]
    try:
        level, mark = marker.read_text(encoding="utf-8").split()
    except (OSError, ValueError):
        level, mark = "none", ""
    if mark != seen:
        level = _judge(text, cache, source_key)
        try:
            cache.mkdir(parents=True, exist_ok=True)
            marker.write_text(f"{level} {seen}", encoding="utf-8")
        except OSError:
            pass
    return level if level != "none" and _target(level) else None


def _judge(text: str, cache: Path, source_key: str) -> str:
    """Unpack the manifest's best set this machine runs into ``cache``; its level or none."""
    try:
        import llvmlite.binding as ll
        import numba

        manifest = json.loads(text)
        if (manifest.get("source_key") != source_key or manifest.get("numba") != numba.__version__
                or manifest.get("python") != python_tag()
                or manifest.get("triple") != ll.get_process_triple()):
            return "none"
        have = level_features()
        level = next((name for name, need in LEVELS.items()
                      if name in manifest.get("levels", {}) and need <= have), None)
        if level is None:
            return "none"
        _unpack(archives() / manifest["levels"][level], cache)
        return level
    except Exception:  # noqa: BLE001 - a prebuilt set is an optimization: compile instead
        return "none"


def _unpack(archive: Path, cache: Path) -> None:
    """Extract ``archive`` beside ``cache`` and move in every kernel not there yet."""
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cache.parent, prefix=".unpack-") as tmp:
        with tarfile.open(archive, "r:xz") as tar:
            if hasattr(tarfile, "data_filter"):  # Python >= 3.10.12 / 3.11.4
                tar.extractall(tmp, filter="data")
            else:  # pragma: no cover - older Pythons: our own archive, plain files only
                tar.extractall(tmp)  # noqa: S202
        root = Path(tmp)
        for index in sorted(root.rglob("*.nbi")):
            dest = cache / index.relative_to(root)
            if dest.exists():  # numba compiled this function here itself: keep its own
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            stem = index.name[:-len(".nbi")]
            for data in sorted(index.parent.glob(f"{stem}.*.nbc")):  # data first, index last
                os.replace(data, dest.parent / data.name)
            os.replace(index, dest)
