"""Text layouts kept from one process to the next, for the renderer of the run's figure and of
sweep.png (`cosim.logs.plot._canvas_class`).

Laying a text out (FreeType shaping each character, once for the text's size and once for its
glyphs' places) is most of what matplotlib spends on a text, ~15 us a character; a run's figure
holds ~100 texts, most of them the same from run to run (legend entries, units, tick labels), and a
run's plot process has only the run's time to lay them out ahead. So what a process measured and
laid out is kept in a file beside the built kernels, read by the next process that draws: per text,
its font files, size [pt], dpi and hinting flags, the text's width, height and descent [px] and,
when every glyph is the first font's (no fallback font), its glyphs (index and offset), packed in
bytes (one object a text: the file is read in ~1 ms, not one Python tuple a glyph).

A font file is known by its path, size and modification time, so a changed font lays its texts out
afresh; the file is named by matplotlib's and FreeType's versions, and holds the rcParams that change
a layout (text.hinting_factor, text.kerning_factor). At most `KEPT` texts are kept: the ones no
process has used for longest go first (a process that writes puts the texts it used last, after
those it added). A process adds what it laid out when it is done drawing (`keep`: a plot process
after it has answered, any other at exit). Whatever goes wrong reading or writing the file only
means the texts are laid out again.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import pickle
import struct
from pathlib import Path

FORMAT = "navcosim text layouts 2"
KEPT = 1000  # texts: ~3 times a run's figure and a sweep's; the file ~0.1 MB, read in ~1 ms
GLYPH = struct.Struct("<idd")  # a glyph's index and its x and y offset [px] (the layout's doubles)

# font id (the font files' (path, face, size, mtime) tuple) -> {(text, size [pt], dpi, flags):
# [(width, height, descent) | None, glyphs (GLYPH after GLYPH) | None]}
_kept: dict | None = None
_added = [0]  # entries this process laid out, not yet written
_used: set = set()  # (font id, key) of the kept texts this process used
_font_ids: dict = {}  # hash(FontProperties) -> font id (or None: not kept), in this process


def kept_path() -> Path:
    """The file, beside the built kernels (`native.load.build_folder`), named by the versions of
    matplotlib and FreeType."""
    import matplotlib
    from matplotlib import ft2font

    from native.load import build_folder

    versions = f"{matplotlib.__version__}-{ft2font.__freetype_version__}"
    return build_folder(Path(__file__)) / f"text-layouts-{versions}.pickle"


def _settings() -> tuple:
    """What besides the font, size, dpi and hinting flags changes a layout: the file's header."""
    import matplotlib

    return (FORMAT, matplotlib.rcParams["text.hinting_factor"], matplotlib.rcParams["text.kerning_factor"])


def _read(path: Path) -> dict:
    try:
        with open(path, "rb") as stream:
            header, entries = pickle.load(stream)
    except Exception:  # noqa: BLE001 - none, unreadable or another format: laid out afresh
        return {}
    return entries if header == _settings() and isinstance(entries, dict) else {}


def _entries() -> dict:
    global _kept
    if _kept is None:
        _kept = _read(kept_path())
    return _kept


def _font_id(prop) -> tuple | None:
    """The files of the fonts `prop` sets its text in (the first one and its fallbacks), each as
    (path, face index, size, modification time); None when one cannot be read."""
    key = hash(prop)  # (FontProperties are equal by hash, as the renderer's own caches take them)
    found = _font_ids.get(key, 0)
    if found != 0:
        return found
    from matplotlib.font_manager import fontManager

    try:  # (matplotlib's own look-up for a text's fonts, as `RendererAgg._prepare_font` does it)
        fonts = fontManager._find_fonts_by_props(prop)
    except Exception:  # noqa: BLE001 - another matplotlib, or no font: nothing kept for it
        fonts = []
    parts = []
    for font in fonts:
        path = str(getattr(font, "path", font))  # (matplotlib's FontPath: the path and the face)
        try:
            stat = os.stat(path)
        except OSError:
            parts = None
            break
        parts.append((path, getattr(font, "face_index", 0), stat.st_size, stat.st_mtime_ns))
    found = _font_ids[key] = None if not parts else tuple(parts)
    return found


def _entry(s: str, prop, dpi: float, flags, create: bool = False) -> list | None:
    font = _font_id(prop)
    if font is None:
        return None
    entries = _entries()
    texts = entries.get(font)
    key = (s, prop.get_size_in_points(), float(dpi), int(getattr(flags, "value", flags)))
    entry = None if texts is None else texts.get(key)
    if entry is None and create:
        if texts is None:
            texts = entries[font] = {}
        entry = texts[key] = [None, None]
    elif entry is not None:
        _used.add((font, key))
    return entry


def size_of(s: str, prop, dpi: float, flags) -> tuple | None:
    """The kept (width, height, descent) [px] of `s` set in `prop` at `dpi` with `flags`, or None."""
    entry = _entry(s, prop, dpi, flags)
    return None if entry is None else entry[0]


def glyphs_of(s: str, prop, dpi: float, flags) -> tuple | None:
    """The kept glyphs of `s` (glyph index, x, y: the layout's), all of the first font of `prop`."""
    entry = _entry(s, prop, dpi, flags)
    return None if entry is None or entry[1] is None else tuple(GLYPH.iter_unpack(entry[1]))


def remember_size(s: str, prop, dpi: float, flags, size: tuple) -> None:
    entry = _entry(s, prop, dpi, flags, create=True)
    if entry is not None and entry[0] is None:
        entry[0] = tuple(float(number) for number in size)
        _added[0] += 1


def remember_glyphs(s: str, prop, dpi: float, flags, glyphs) -> None:
    """Keep the layout `glyphs` ((glyph index, x, y) of each glyph, all of the first font)."""
    entry = _entry(s, prop, dpi, flags, create=True)
    if entry is not None and entry[1] is None:
        entry[1] = b"".join(GLYPH.pack(int(glyph), float(x), float(y)) for glyph, x, y in glyphs)
        _added[0] += 1


def keep() -> None:
    """Add what this process laid out to the file (with what other processes added meanwhile), the
    texts unused for longest dropped beyond `KEPT`; nothing when it laid nothing out."""
    if not _added[0] or _kept is None:
        return
    _added[0] = 0
    path = kept_path()
    if not path.parent.is_dir():  # (no kernels built there: nothing of navcosim's to write beside;
        return  # and a folder removed meanwhile, by a test or the user, is not made again)
    try:
        with _locked(path):  # (a run's plot process and its helper write at about the same time)
            _write_merged(path)
    except OSError:  # not kept: the next process lays them out again
        pass


@contextlib.contextmanager
def _locked(path: Path):
    """Hold an exclusive lock on a file beside `path` (where fcntl has it) while the block reads,
    merges and writes `path`: a writer that comes meanwhile reads what this one wrote."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(path.with_name(f".{path.name}.lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _write_merged(path: Path) -> None:
    merged = _read(path)
    for font, key in _used:  # last, after the file's others: used now
        texts = merged.get(font)
        if texts is not None and key in texts:
            texts[key] = texts.pop(key)
    for font, texts in _kept.items():  # (what this process added comes after them)
        merged.setdefault(font, {}).update(texts)
    count = sum(len(texts) for texts in merged.values())
    for texts in merged.values():  # the texts unused for longest go first
        while count > KEPT and texts:
            del texts[next(iter(texts))]
            count -= 1
    partial = path.with_name(f".{path.name}.{os.getpid()}")
    try:
        with open(partial, "wb") as stream:
            pickle.dump((_settings(), merged), stream, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(partial, path)
    except Exception:  # noqa: BLE001 - not kept: the next process lays them out again
        try:
            partial.unlink(missing_ok=True)
        except OSError:
            pass


atexit.register(keep)  # (a forked plot process leaves with os._exit: it calls `keep` itself)


def forget() -> None:
    """Drop what this process read or laid out (tests; a process whose fonts changed)."""
    global _kept
    _kept = None
    _added[0] = 0
    _used.clear()
    _font_ids.clear()
