"""The one output guard: every verb calls :func:`check_paths` before any work.

Every output a command would write (its files, and for folder outputs the files it
writes inside the folder) is checked against every input and every other output:

* not the same file as an input or another output, after resolving relative paths,
  ``..``, symbolic links and hard links (a refusal names both paths and options);
* a supported format: the extension the readers of that kind of file expect (NPZ,
  NetCDF, ZIP, JSON, HDF5; or none) or a figure format matplotlib writes;
* its folder exists and is writable, and the path is not a folder;
* every file name, input or output, is valid UTF-8 (mdaug records names in its
  outputs' settings);
* no output file exists already, unless the command was given ``--overwrite`` (every
  verb has it, :func:`.common.add_verb`): no silent overwrite. Outputs a command
  resumes from are exempt: a chain checkpoint, a work folder's caches (``inside``
  names ending in ``/``) and a folder whose own rule decides (``resumes``: the
  study's folder, :func:`mdaug.reports.identity.check_study_folder`).

Nothing heavy is imported: the guard runs in milliseconds.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

PLOT_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")
"""Figure formats :func:`mdaug.radar.plots.save_figure` writes (no suffix = PNG);
pgf (needs LaTeX) and raw/rgba (no header) are left out."""

KINDS = {
    "npz": (".npz", ""),
    "posterior": (".nc", ""),
    "model": (".zip", ""),
    "json": (".json", ""),
    "checkpoint": (".h5", ".hdf5", ""),
    "plot": tuple(f".{f}" for f in PLOT_FORMATS) + ("",),
    "folder": None,
}
"""The extensions each kind of output may have ("" = none); any other extension names
another format (a ``.csv`` or ``.mat`` NPZ would be misread later) and is refused."""
WHAT = {"npz": "an NPZ file", "posterior": "a NetCDF posterior", "model": "a model ZIP", "json": "a JSON file",
        "checkpoint": "an HDF5 chain checkpoint", "plot": "a figure"}


@dataclass
class Output:
    """One output of a command: ``option`` (e.g. ``--out``), ``path`` (None = not asked
    for), ``kind`` (a key of :data:`KINDS`), and for a folder the files written in it
    (``inside``, relative names; a name ending in ``/`` is a subfolder it fills) and further files written beside a file (``beside``,
    full paths, e.g. a checkpoint's fit). ``resumes``: the command resumes from what
    the output holds (its own rule decides), so an existing one is not refused."""

    option: str
    path: object
    kind: str
    inside: tuple = ()
    beside: tuple = field(default_factory=tuple)
    resumes: bool = False


def shown(path) -> str:
    """A path as text that can always be printed (undecodable bytes as \\x escapes)."""
    return os.fsencode(str(path)).decode("utf-8", "backslashreplace")


def _error(message: str):
    from ..radar import DataFileError

    return DataFileError(message)


def _check_name(option: str, path) -> None:
    try:
        os.fsencode(str(path)).decode("utf-8")
    except UnicodeDecodeError:
        raise _error(f"{shown(path)}: {option}: the file name is not valid UTF-8; rename it (mdaug records file "
                     "names in its outputs)") from None


def _identity(path: Path):
    """(real path, (device, inode) or None) of a path."""
    real = os.path.realpath(path)
    try:
        st = os.stat(real)
        return real, (st.st_dev, st.st_ino)
    except OSError:
        return real, None


def _same(a, b) -> bool:
    return a[0] == b[0] or (a[1] is not None and a[1] == b[1])


def _check_format(out: Output) -> None:
    allowed = KINDS[out.kind]
    if allowed is None:
        return
    suffix = Path(out.path).suffix.lower()
    if suffix not in allowed:
        listed = ", ".join(s for s in allowed if s)
        extra = (" (or none: PNG)" if out.kind == "plot" else " (or none)") if "" in allowed else ""
        raise _error(f"{shown(out.path)}: {out.option} must be {WHAT[out.kind]} ending in {listed}{extra}; "
                     f"got {'no extension' if not suffix else repr(suffix)}")


def _check_folder(out: Output) -> None:
    path = Path(out.path)
    if path.exists() and not path.is_dir():
        raise _error(f"{shown(path)}: {out.option} must be a folder, found a file")
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise _error(f"{shown(path)}: cannot create {out.option}, {shown(probe)} is a file")
    if not os.access(probe, os.W_OK):
        raise _error(f"{shown(path)}: cannot write {out.option}, folder {shown(probe)} is not writable")


def _check_file(out: Output) -> None:
    from ..radar import check_writable

    check_writable(out.path)


def _check_existing(out: Output) -> None:
    """The one no-silent-overwrite rule: an output file that exists is refused."""
    if out.resumes or out.kind == "checkpoint":
        return
    if out.kind == "folder":
        files = [Path(out.path) / name for name in out.inside if not name.endswith("/")]
    else:
        files = [Path(out.path)]
    for path in files + [Path(p) for p in out.beside]:
        if os.path.lexists(path):
            where = "" if path == Path(out.path) else f" (a file {out.option} {shown(out.path)} would hold)"
            raise _error(f"{shown(path)}: {out.option}: the file exists{where}; give --overwrite to replace it, "
                         "or choose another path")


def check_paths(inputs=(), outputs=(), overwrite: bool = False) -> None:
    """Refuse, before any work, a command whose outputs would overwrite an input or
    each other, or cannot be written, or exist already (unless ``overwrite``, the
    verb's ``--overwrite``) (see the module doc).

    inputs: (option or role, path) pairs (None paths skipped); outputs:
    :class:`Output` objects. Raises :class:`mdaug.radar.DataFileError` naming the
    paths and options involved.
    """
    inputs = [(o, Path(p)) for o, p in inputs if p is not None]
    outputs = [o for o in outputs if o.path is not None]
    for option, path in inputs:
        _check_name(option, path)
    written, trees = [], []  # (option, path) of every file the command writes; of every folder it fills
    for out in outputs:
        _check_name(out.option, out.path)
        if out.kind == "folder":
            _check_folder(out)
            written += [(out.option, Path(out.path) / name) for name in out.inside if not name.endswith("/")]
            trees += [(out.option, Path(out.path) / name) for name in out.inside if name.endswith("/")]
        else:
            _check_file(out)
            written.append((out.option, Path(out.path)))
        written += [(out.option, Path(p)) for p in out.beside]
    ids_in = [(o, p, _identity(p)) for o, p in inputs]
    for t_opt, tree in trees:
        root = os.path.realpath(tree) + os.sep
        for i_opt, i_path, i_id in ids_in:
            if i_id[0].startswith(root):
                raise _error(f"{shown(i_path)}: the input {i_opt} lies in {shown(tree)}, which {t_opt} fills with "
                             "the command's own files; move the input or choose another output folder")
    ids_out = [(o, p, _identity(p)) for o, p in written]
    for k, (o_opt, o_path, o_id) in enumerate(ids_out):
        for i_opt, i_path, i_id in ids_in:
            if _same(o_id, i_id):
                sep = "" if i_opt.endswith("=") else " "  # --fit HELI=p.nc
                raise _error(f"{shown(o_path)}: {o_opt} would overwrite the input {i_opt}{sep}{shown(i_path)} (the "
                             "same file); choose another output path")
        for o2_opt, o2_path, o2_id in ids_out[:k]:
            if _same(o_id, o2_id):
                raise _error(f"{shown(o_path)}: {o_opt} and {o2_opt} {shown(o2_path)} are the same file; two "
                             "outputs of one command need two paths")
    for out in outputs:  # formats after: a clash with an input is the graver news
        if out.kind != "folder":
            _check_format(out)
    if not overwrite:
        for out in outputs:
            _check_existing(out)
