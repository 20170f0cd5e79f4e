"""Layout detection: which light-field folder format a path holds, and where its files are.

Scanning only lists folders and reads small text files (``parameters.cfg``,
``attributes.dat``); no pixels are decoded here.
"""

from __future__ import annotations

import configparser
import dataclasses
import os
import re
from collections.abc import Mapping

from ._images import IMAGE_EXTENSIONS

Position = tuple[int, int]

HCI4D = "hci4d"
HCI_OLD = "hci_old"
VIEW_GRID = "view_grid"
LAYOUTS = (HCI4D, HCI_OLD, VIEW_GRID)


@dataclasses.dataclass(frozen=True)
class LayoutInfo:
    """What a light-field folder contains (the result of `detect_layout`).

    Grid positions are 0-based ``(row, col)`` in the SPEC convention (rows top to bottom,
    columns left to right); ``row_labels``/``col_labels`` give the index each grid row/column
    carries in the file names (e.g. ``(9, 10, 11)`` for Stanford ``09_08.png`` … ``11_10.png``).

    Attributes:
        layout: ``"hci4d"``, ``"hci_old"`` or ``"view_grid"``.
        folder: absolute path of the scene folder.
        pattern: human-readable file naming, e.g. ``"input_Cam{k:03d}.png, k = 9*row + col"``.
        grid: ``(U, V)`` of the full grid in the folder.
        files: grid position → view file (absolute path); absent positions are missing views.
        row_labels: file-name index of each grid row, length ``U``.
        col_labels: file-name index of each grid column, length ``V``.
        gt_files: grid position → ground-truth file (PFM disparity, or old-HCI ``depth.bin``).
        gt_mask_files: grid position → validity mask image (non-zero = valid GT).
        gt_format: ``"pfm"``, ``"hci_old_depth"`` or ``None``.
        depth_to_disparity: old HCI ``(dH, focal_length, shift)`` with
            ``disparity = dH * focal_length / depth - shift`` (``focal_length = 0``: the file
            already holds disparity); ``None`` otherwise.
        gt_size: ``(H, W)`` of raw ground truth that carries no header (``depth.bin``).
        disparity_range: ``(d_min, d_max)`` in pixels per view step from the metadata.
        transposed: True when file rows/columns were swapped to match the parallax (view grids).
        window: ``(row0, col0, U', V')`` of an angular crop applied on loading, else ``None``.
        scale: spatial scale applied on loading, else ``None``.
        image_size: ``(H, W)`` of the views in the files (before scaling), set on loading.
        notes: remarks for humans (e.g. how the orientation was decided).
    """

    layout: str
    folder: str
    pattern: str
    grid: tuple[int, int]
    files: Mapping[Position, str]
    row_labels: tuple[int, ...]
    col_labels: tuple[int, ...]
    gt_files: Mapping[Position, str] = dataclasses.field(default_factory=dict)
    gt_mask_files: Mapping[Position, str] = dataclasses.field(default_factory=dict)
    gt_format: str | None = None
    depth_to_disparity: tuple[float, float, float] | None = None
    gt_size: tuple[int, int] | None = None
    disparity_range: tuple[float, float] | None = None
    transposed: bool = False
    window: tuple[int, int, int, int] | None = None
    scale: float | None = None
    image_size: tuple[int, int] | None = None
    notes: tuple[str, ...] = ()

    @property
    def centre(self) -> Position:
        """``(U // 2, V // 2)``."""
        return self.grid[0] // 2, self.grid[1] // 2

    def describe_position(self, pos: Position) -> str:
        """``"(row, col) = (r, c) [file labels RR_CC]"`` for error messages."""
        r, c = pos
        lr, lc = self.row_labels[r], self.col_labels[c]
        if self.transposed:
            lr, lc = lc, lr
        if self.layout == HCI4D:
            return f"(row, col) = ({r}, {c}) [input_Cam{lr * len(self.col_labels) + lc:03d}.png]"
        return f"(row, col) = ({r}, {c}) [file indices {lr:02d}_{lc:02d}]"

    def with_(self, **changes) -> LayoutInfo:
        """A copy with some fields replaced."""
        return dataclasses.replace(self, **changes)


def _listdir(folder: str) -> list[str]:
    try:
        return sorted(os.listdir(folder))
    except PermissionError as e:
        raise PermissionError(f"cannot list light field folder {folder}: {e}") from None


def _check_folder(path: str | os.PathLike) -> str:
    folder = os.path.abspath(os.fspath(path))
    if not os.path.exists(folder):
        raise FileNotFoundError(f"light field folder not found: {folder}")
    if not os.path.isdir(folder):
        raise NotADirectoryError(
            f"expected a light field folder, got a file: {folder} (pass the folder that holds "
            "the views)"
        )
    return folder


def _is_image(name: str) -> bool:
    return os.path.splitext(name)[1].lower() in IMAGE_EXTENSIONS


# ---- HCI 4D -------------------------------------------------------------------------------

_HCI_VIEW = re.compile(r"^input_Cam(\d+)\.png$", re.IGNORECASE)
_HCI_GT = re.compile(r"^gt_disp_lowres(?:_Cam(\d+))?\.pfm$", re.IGNORECASE)


def read_hci_parameters(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """Parse an HCI 4D ``parameters.cfg`` (INI) into ``{section: {key: value}}``.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not valid INI.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"parameters file not found: {path}")
    cfg = configparser.ConfigParser()
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            cfg.read_file(f)
    except configparser.Error as e:
        raise ValueError(f"malformed HCI parameters file {path}: {e}") from None
    return {s: dict(cfg[s]) for s in cfg.sections()}


def _float_opt(params: dict, section: str, key: str, path: str) -> float | None:
    if key not in params.get(section, {}):
        return None
    try:
        return float(params[section][key])
    except ValueError:
        raise ValueError(
            f"{path}: [{section}] {key} = {params[section][key]!r} is not a number"
        ) from None


def _scan_hci4d(folder: str, names: list[str]) -> LayoutInfo:
    cams: dict[int, str] = {}
    for n in names:
        if m := _HCI_VIEW.match(n):
            k = int(m.group(1))
            if k in cams:
                raise ValueError(
                    f"ambiguous HCI 4D folder {folder}: {cams[k]} and {n} both name camera "
                    f"{k:03d}; remove one of them"
                )
            cams[k] = n
    cfg_path = os.path.join(folder, "parameters.cfg")
    nx = ny = None
    drange = None
    notes = []
    if os.path.isfile(cfg_path):
        params = read_hci_parameters(cfg_path)
        fx = _float_opt(params, "extrinsics", "num_cams_x", cfg_path)
        fy = _float_opt(params, "extrinsics", "num_cams_y", cfg_path)
        nx = int(fx) if fx is not None else None
        ny = int(fy) if fy is not None else None
        dmin = _float_opt(params, "meta", "disp_min", cfg_path)
        dmax = _float_opt(params, "meta", "disp_max", cfg_path)
        if dmin is not None and dmax is not None:
            if not dmin < dmax:
                raise ValueError(f"{cfg_path}: disp_min {dmin} is not below disp_max {dmax}")
            drange = (dmin, dmax)
    else:
        notes.append("no parameters.cfg: 9x9 grid assumed, no disparity range")
    if nx is None or ny is None:
        n = 9
        while n * n <= max(cams):
            n += 1
        nx = nx or n
        ny = ny or n
    if nx <= 0 or ny <= 0:
        raise ValueError(f"{cfg_path}: invalid camera grid num_cams_x={nx}, num_cams_y={ny}")
    too_big = sorted(k for k in cams if k >= nx * ny)
    if too_big:
        raise ValueError(
            f"HCI 4D folder {folder}: camera index {too_big[0]:03d} does not fit the "
            f"{ny}x{nx} grid (num_cams_y x num_cams_x)"
        )
    files = {(k // nx, k % nx): os.path.join(folder, n) for k, n in cams.items()}
    gt_files = {}
    centre = (ny // 2, nx // 2)
    for n in names:
        m = _HCI_GT.match(n)
        if not m:
            continue
        if m.group(1) is None:
            gt_files.setdefault(centre, os.path.join(folder, n))
        else:
            k = int(m.group(1))
            if k >= nx * ny:
                raise ValueError(f"ground truth {n} in {folder} does not fit the {ny}x{nx} grid")
            gt_files[(k // nx, k % nx)] = os.path.join(folder, n)  # per-camera file wins
    return LayoutInfo(
        layout=HCI4D,
        folder=folder,
        pattern=f"input_Cam{{k:03d}}.png, k = {nx}*row + col",
        grid=(ny, nx),
        files=files,
        row_labels=tuple(range(ny)),
        col_labels=tuple(range(nx)),
        gt_files=gt_files,
        gt_format="pfm" if gt_files else None,
        disparity_range=drange,
        notes=tuple(notes),
    )


# ---- view grids: RR_CC.png, view_RR_CC.png, <name>_RR_CC.png, <name>_NNN_RR_CC.png -------

_GRID_STEM = re.compile(r"^(?:(?P<prefix>.*)_)?(?P<r>\d+)_(?P<c>\d+)$")


def _split_index(prefix: str) -> tuple[str, str | None]:
    """``"IMG_0001_007"`` → ``("IMG_0001", "007")``; a prefix without a numeric tail → None."""
    head, _, tail = prefix.rpartition("_")
    if tail.isdigit():
        return head, tail
    return prefix, None


def _grid_files(folder: str, names: list[str]) -> tuple[str, dict[tuple[int, int], str]] | None:
    """Match view-grid file names. Returns (pattern, {(row label, col label): path}) or None."""
    matches = []  # (prefix or None, ext, r, c, name)
    for n in names:
        if not _is_image(n):
            continue
        stem, ext = os.path.splitext(n)
        m = _GRID_STEM.match(stem)
        if m:
            matches.append((m.group("prefix"), ext, int(m.group("r")), int(m.group("c")), n))
    if not matches:
        return None
    groups: dict[tuple[str | None, str], list] = {}
    for prefix, ext, r, c, n in matches:
        groups.setdefault((prefix, ext.lower()), []).append((r, c, n, None))
    if len(groups) > 1:
        # Several prefixes: a per-view running index <name>_NNN_RR_CC?
        split: dict[tuple[str | None, str], list] = {}
        for prefix, ext, r, c, n in matches:
            head, idx = _split_index(prefix) if prefix is not None else (None, None)
            if idx is None:
                split = {}
                break
            split.setdefault((head, ext.lower()), []).append((r, c, n, idx))
        if len(split) != 1:
            found = sorted(groups, key=lambda g: -len(groups[g]))
            desc = ", ".join(
                f"{(p + '_') if p else ''}RR_CC{e} ({len(groups[(p, e)])} files)"
                for p, e in found[:6]
            )
            raise ValueError(
                f"ambiguous view grid in {folder}: several file families match "
                f"[prefix_]RR_CC: {desc}. Put one light field per folder."
            )
        groups = split
    (prefix, ext), items = next(iter(groups.items()))
    has_index = items[0][3] is not None
    pos: dict[tuple[int, int], str] = {}
    for r, c, n, _ in items:
        if (r, c) in pos:
            raise ValueError(
                f"two files for view {r:02d}_{c:02d} in {folder}: "
                f"{os.path.basename(pos[(r, c)])} and {n}"
            )
        pos[(r, c)] = os.path.join(folder, n)
    name = "" if not prefix else prefix + "_"
    pattern = f"{name}{'NNN_' if has_index else ''}RR_CC{ext}"
    return pattern, pos


def _labels_to_grid(
    labelled: dict[tuple[int, int], str],
) -> tuple[tuple[int, ...], tuple[int, ...], dict[Position, str]]:
    rows = sorted({r for r, _ in labelled})
    cols = sorted({c for _, c in labelled})
    row_labels = tuple(range(rows[0], rows[-1] + 1))
    col_labels = tuple(range(cols[0], cols[-1] + 1))
    files = {(r - rows[0], c - cols[0]): p for (r, c), p in labelled.items()}
    return row_labels, col_labels, files


def _label_note(row_labels, col_labels) -> str:
    return (
        f"file rows {row_labels[0]:02d}-{row_labels[-1]:02d}, "
        f"cols {col_labels[0]:02d}-{col_labels[-1]:02d}"
    )


def _scan_view_grid(folder: str, names: list[str]) -> LayoutInfo | None:
    found = _grid_files(folder, names)
    if found is None:
        return None
    pattern, labelled = found
    row_labels, col_labels, files = _labels_to_grid(labelled)
    return LayoutInfo(
        layout=VIEW_GRID,
        folder=folder,
        pattern=pattern,
        grid=(len(row_labels), len(col_labels)),
        files=files,
        row_labels=row_labels,
        col_labels=col_labels,
        notes=(_label_note(row_labels, col_labels),),
    )


# ---- old HCI (Wanner et al. 2013, as re-packaged: lf/RR_CC.png + attributes.dat) ---------


def read_hci_old_attributes(path: str | os.PathLike) -> dict[str, float]:
    """Parse an old-HCI ``attributes.dat`` (lines ``value //name``) into ``{name: value}``.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: on a line that is not ``number //name``.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"attributes file not found: {path}")
    out: dict[str, float] = {}
    with open(path, encoding="utf-8", errors="replace") as f:
        for i, line in enumerate(f, 1):
            if not line.strip():
                continue
            value, sep, key = line.partition("//")
            try:
                out[key.strip()] = float(value)
            except ValueError:
                raise ValueError(
                    f"{path}:{i}: expected 'number //name', got {line.strip()!r}"
                ) from None
            if not sep:
                raise ValueError(f"{path}:{i}: expected 'number //name', got {line.strip()!r}")
    return out


def _scan_hci_old(folder: str) -> LayoutInfo:
    lf_dir = os.path.join(folder, "lf")
    attr_path = os.path.join(folder, "attributes.dat")
    attrs = read_hci_old_attributes(attr_path)
    missing = [k for k in ("xRes", "yRes", "hRes", "vRes") if k not in attrs]
    if missing:
        raise ValueError(f"{attr_path} lacks {', '.join(missing)}")
    found = _grid_files(lf_dir, _listdir(lf_dir))
    if found is None:
        raise ValueError(f"old HCI folder {folder}: no views named RR_CC.png in {lf_dir}")
    pattern, labelled = found
    row_labels, col_labels, files = _labels_to_grid(labelled)
    U, V = len(row_labels), len(col_labels)
    if (int(attrs["vRes"]), int(attrs["hRes"])) != (U, V):
        raise ValueError(
            f"{attr_path} declares {int(attrs['vRes'])}x{int(attrs['hRes'])} views "
            f"(vRes x hRes) but {lf_dir} holds a {U}x{V} grid"
        )
    centre = (U // 2, V // 2)
    gt_files, mask_files = {}, {}
    conv = None
    depth_path = os.path.join(folder, "depth.bin")
    if os.path.isfile(depth_path):
        gt_files[centre] = depth_path
        need = [k for k in ("dH", "focalLength", "shift") if k not in attrs]
        if need:
            raise ValueError(f"{attr_path} lacks {', '.join(need)} needed to convert depth.bin")
        conv = (attrs["dH"], attrs["focalLength"], attrs["shift"])
        mask_path = os.path.join(folder, "mask.png")
        if os.path.isfile(mask_path):
            mask_files[centre] = mask_path
    drange = None
    if "min_disp" in attrs and "max_disp" in attrs:
        drange = (attrs["min_disp"], attrs["max_disp"])
    return LayoutInfo(
        layout=HCI_OLD,
        folder=folder,
        pattern="lf/" + pattern + " + attributes.dat",
        grid=(U, V),
        files=files,
        row_labels=row_labels,
        col_labels=col_labels,
        gt_files=gt_files,
        gt_mask_files=mask_files,
        gt_format="hci_old_depth" if gt_files else None,
        depth_to_disparity=conv,
        gt_size=(int(attrs["yRes"]), int(attrs["xRes"])),
        disparity_range=drange,
        notes=(_label_note(row_labels, col_labels),),
    )


# ---- detection ----------------------------------------------------------------------------


def detect_layout(path: str | os.PathLike) -> LayoutInfo:
    """Find which light-field layout a folder holds (lists files; decodes no pixels).

    Recognised, in this order:

    - ``hci_old``: ``lf/RR_CC.png`` + ``attributes.dat`` (+ ``depth.bin``, ``mask.png``);
      the ``lf`` sub-folder itself is accepted too.
    - ``hci4d``: ``input_Cam{k:03d}.png`` (+ ``parameters.cfg``, ``gt_disp_lowres*.pfm``).
    - ``view_grid``: ``[prefix_][NNN_]RR_CC.<png|jpg|…>`` with any first index (0-, 1-based or
      an offset sub-grid such as rows 09–11).

    Args:
        path: the scene folder.

    Returns:
        A `LayoutInfo` describing the full grid (no crop, no scaling).

    Raises:
        FileNotFoundError: if the folder does not exist.
        NotADirectoryError: if ``path`` is a file.
        ValueError: if no layout is recognised (the message lists what the folder holds) or
            the metadata contradicts the files.
    """
    folder = _check_folder(path)
    names = _listdir(folder)
    if os.path.isdir(os.path.join(folder, "lf")) and "attributes.dat" in names:
        return _scan_hci_old(folder)
    parent = os.path.dirname(folder)
    if os.path.basename(folder) == "lf" and os.path.isfile(os.path.join(parent, "attributes.dat")):
        return _scan_hci_old(parent)
    if any(_HCI_VIEW.match(n) for n in names):
        return _scan_hci4d(folder, names)
    grid = _scan_view_grid(folder, names)
    if grid is not None:
        return grid
    shown = ", ".join(names[:8]) + (f", … ({len(names)} entries)" if len(names) > 8 else "")
    raise ValueError(
        f"no recognised light-field layout in {folder}: expected input_CamNNN.png (HCI 4D), "
        "lf/RR_CC.png + attributes.dat (old HCI) or views named [prefix_][NNN_]RR_CC.png; "
        f"found: {shown or 'an empty folder'}"
    )
