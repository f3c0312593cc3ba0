"""Seeded fuzz cases for every reader: mutated valid files and structurally odd ones.

A case is ``(label, read)``: ``read()`` writes its input under a folder and calls one reader.
:func:`outcome` runs it and says ``"ok"`` (a valid stream came back), ``"typed"`` (a typed error
that is a ``ValueError`` and names the file) or ``"untyped: ..."`` (anything else, a defect).
Same seed, same cases: a failing case is reproduced by its reader name and index.
"""

from __future__ import annotations

import gzip
import io
import json
import struct
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from neuspike.errors import InputError, NeuSpikeError
from neuspike.streams import EventStream, SpikeStream
from tests.neuspike.formats.aedat4_encoder import encode_aedat4

READERS = ("dat", "spike_npz", "events_npz", "h5", "txt", "aedat4")
W, H = 16, 8

_BYTES = (0x00, 0x01, 0x7F, 0x80, 0xFF, 0x30, 0x39, 0x0A, 0x20)
_INTS = (0, 1, -1, 2, 255, 65535, 2**31 - 1, -2**31, 2**32 - 1, 10**6, 10**9)
_NUMBERS: tuple[Any, ...] = (0, 1, -1, 0.5, 2.0, float("nan"), float("inf"), -float("inf"), 1e20, 2**63, 1e308,
                             20_000, 16, 8, 65_536, 70_000)
_TOKENS = ("nan", "inf", "-inf", "-1", "0", "1", "2", "1e20", "1e400", "99999999999999999999", "0x10", "",
           "\x00", "1.5", "é", "\xff", "-0", "16", "8", "+1", "1e-300", "abc")


# --------------------------------------------------------------------------- mutation
def mutate(data: bytes, rng: np.random.Generator, *, head: int = 512) -> bytes:
    """One to three random edits of ``data``; half of them aim at the first ``head`` bytes."""
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 4))):
        n = len(b)
        span = min(n, head) if rng.random() < 0.5 else n
        pos = int(rng.integers(0, max(span, 1)))
        kind = int(rng.integers(7))
        if kind == 0 and n:                                       # bit flip
            b[min(pos, n - 1)] ^= 1 << int(rng.integers(8))
        elif kind == 1 and n:                                     # interesting byte
            b[min(pos, n - 1)] = _BYTES[int(rng.integers(len(_BYTES)))]
        elif kind == 2 and n >= 8:                                # interesting 32- or 64-bit integer
            v = _INTS[int(rng.integers(len(_INTS)))]
            raw = struct.pack("<q", v) if rng.random() < 0.3 else struct.pack("<I", v % 2**32)
            pos = min(pos, n - len(raw))
            b[pos:pos + len(raw)] = raw
        elif kind == 3:                                           # truncate
            del b[int(rng.integers(0, n + 1)):]
        elif kind == 4:                                           # insert random bytes
            b[pos:pos] = rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8).tobytes()
        elif kind == 5 and n:                                     # delete a chunk
            del b[pos:pos + int(rng.integers(1, 17))]
        elif n:                                                   # duplicate a chunk
            at = int(rng.integers(0, n))
            b[pos:pos] = b[at:at + int(rng.integers(1, 33))]
    return bytes(b)


def mutate_text(text: str, rng: np.random.Generator) -> str:
    """Replace, insert or drop whitespace-separated tokens (and sometimes line breaks)."""
    parts = text.split(" ")
    for _ in range(int(rng.integers(1, 4))):
        i = int(rng.integers(len(parts)))
        tok = _TOKENS[int(rng.integers(len(_TOKENS)))]
        kind = int(rng.integers(4))
        if kind == 0:
            parts[i] = tok
        elif kind == 1:
            parts[i] = parts[i] + tok
        elif kind == 2:
            parts.insert(i, tok)
        elif len(parts) > 1:
            parts.pop(i)
    out = " ".join(parts)
    if rng.random() < 0.2:
        out = out.replace("\n", " ", 1)
    return out


def _pick(rng: np.random.Generator, pool: tuple[Any, ...]) -> Any:
    return pool[int(rng.integers(len(pool)))]


# --------------------------------------------------------------------------- valid seeds
def _events(rng: np.random.Generator, n: int = 40) -> EventStream:
    t = np.sort(rng.random(n)) * 0.01
    return EventStream(t, rng.integers(0, W, n), rng.integers(0, H, n), np.where(rng.random(n) < 0.5, -1, 1),
                       W, H)


def _npz_bytes(compressed: bool = False, **arrays: Any) -> bytes:
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **arrays)
    return buf.getvalue()


def _h5_bytes(build: Callable[[Any], None]) -> bytes:
    import h5py

    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        build(f)
    return buf.getvalue()


def seed_files(rng: np.random.Generator) -> dict[str, list[tuple[str, bytes]]]:
    """Valid files of every format, small (a few kB), as ``{reader: [(file name, bytes)]}``."""
    ev = _events(rng)
    planes = rng.random((4, H, W)) < 0.3
    common = _h5_bytes(lambda f: (f.create_group("events"),
                                  f["events"].create_dataset("xs", data=ev.x),
                                  f["events"].create_dataset("ys", data=ev.y),
                                  f["events"].create_dataset("ts", data=ev.t_s),
                                  f["events"].create_dataset("ps", data=(ev.p > 0).astype(np.uint8)),
                                  f.attrs.__setitem__("sensor_resolution", np.array([H, W]))))
    rec = np.zeros(len(ev), [("timestamp", "<i8"), ("x", "<u2"), ("y", "<u2"), ("polarity", "u1")])
    rec["timestamp"], rec["x"], rec["y"], rec["polarity"] = np.round(ev.t_s * 1e6), ev.x, ev.y, ev.p > 0
    pku = _h5_bytes(lambda f: f.create_dataset("events", data=rec))
    text = f"{W} {H}\n" + "".join(f"{t:.9f} {x} {y} {int(p > 0)}\n" for t, x, y, p in zip(ev.t_s, ev.x, ev.y, ev.p))
    meta = json.dumps({"stages": [{"name": "integrate_and_fire", "seconds": 0.5}], "seed": 3})
    spike_own = dict(planes=planes, plane_rate_hz=np.float64(20_000), start_s=np.float64(0.0),
                     gain=np.float64(0.25), threshold=np.float64(1.0), meta_json=np.array(meta))
    return {
        "dat": [("s.dat", np.packbits(planes[:, ::-1].reshape(-1), bitorder="little").tobytes())],
        "spike_npz": [("s.npz", _npz_bytes(**spike_own)), ("c.npz", _npz_bytes(True, **spike_own)),
                      ("z.npz", _npz_bytes(spk=planes.astype(np.uint8), label=np.int64(3)))],
        "events_npz": [("e.npz", _npz_bytes(t_s=ev.t_s, x=ev.x, y=ev.y, p=ev.p, width=np.int64(W),
                                            height=np.int64(H)))],
        "h5": [("e.h5", common), ("pku.h5", pku)],
        "txt": [("e.txt", text.encode()), ("e.txt.gz", gzip.compress(text.encode(), mtime=0))],
        "aedat4": [("e.aedat4", encode_aedat4(np.round(ev.t_s * 1e6), ev.x, ev.y, ev.p > 0, width=W, height=H,
                                              per_packet=16))],
    }


# --------------------------------------------------------------------------- structural oddities
def _odd_array(rng: np.random.Generator, base: np.ndarray) -> np.ndarray:
    """``base`` with one of: another shape, another dtype, odd values, or nothing changed."""
    kind = int(rng.integers(7))
    if kind == 0 or base.dtype.kind not in "biuf":
        return np.asarray(_pick(rng, _NUMBERS))                   # a scalar
    if kind == 1:
        return base.reshape(-1)[: int(rng.integers(0, base.size + 1))].copy()
    if kind == 2:
        return base.astype(_pick(rng, (np.float64, np.int64, np.uint8, np.complex64, np.bool_, "U3", "S2")))
    if kind == 3:
        a = base.astype(np.float64)
        if a.size:
            a.reshape(-1)[int(rng.integers(a.size))] = _pick(rng, _NUMBERS)
        return a
    if kind == 4:
        return base.reshape((1,) + base.shape)
    if kind == 5:
        return np.zeros((0,) + base.shape[1:], base.dtype)
    return base


def _odd_npz(rng: np.random.Generator, arrays: dict[str, np.ndarray], compressed: bool) -> bytes:
    out = dict(arrays)
    for key in list(out):
        if rng.random() < 0.3:
            out[key] = _odd_array(rng, np.asarray(out[key]))
        if rng.random() < 0.05:
            del out[key]
    if "meta_json" in out and rng.random() < 0.3:
        depth = int(_pick(rng, (1, 10, 1000, 100_000)))
        out["meta_json"] = np.array(_pick(rng, ("[" * depth + "]" * depth, "{" * depth, "3", "null",
                                                "not json", '{"a": 1}')))
    return _npz_bytes(compressed, **out)


def _huge_npy_header(shape: tuple[int, ...], dtype: str = "|b1") -> bytes:
    """A .npy member whose header declares ``shape`` but which holds a few bytes of data."""
    header = repr({"descr": dtype, "fortran_order": False, "shape": shape}).encode()
    header += b" " * (-(10 + len(header) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + bytes(16)


def _odd_h5(rng: np.random.Generator, ev: EventStream) -> bytes:
    import h5py

    def build(f: Any) -> None:
        if rng.random() < 0.7:
            g = f.create_group("events")
            base = {"xs": ev.x, "ys": ev.y, "ts": ev.t_s, "ps": (ev.p > 0).astype(np.uint8)}
            for key, a in base.items():
                if rng.random() < 0.05:
                    continue
                kind = int(rng.integers(6))
                if kind == 0:
                    g.create_dataset(key, data=_pick(rng, _NUMBERS))                   # scalar
                elif kind == 1:
                    g.create_dataset(key, shape=(10**9,), dtype=a.dtype, chunks=(1024,))  # declared, never stored
                elif kind == 2:
                    g.create_dataset(key, data=np.array([b"ab", b"cd"]))
                elif kind == 3:
                    g.create_dataset(key, data=h5py.Empty("f"))
                else:
                    odd = _odd_array(rng, a)
                    g.create_dataset(key, data=odd.astype("S") if odd.dtype.kind == "U" else odd)
            if rng.random() < 0.8:
                f.attrs["sensor_resolution"] = _pick(rng, (
                    np.array([H, W]), np.array([np.inf, 8]), np.array([np.nan, 8]), np.array([0, 8]),
                    np.array([-1, 8]), "abc", np.array([1e20, 8]), np.array([H]), np.array([H, W, 1]),
                    np.array([H + 0.5, W]), np.array([2.0**70, 8.0]), np.array([[H, W]]), 3))
        else:
            rec = np.zeros(len(ev), [("timestamp", "<i8"), ("x", "<u2"), ("y", "<u2"), ("polarity", "u1")])
            rec["timestamp"], rec["x"], rec["y"], rec["polarity"] = np.round(ev.t_s * 1e6), ev.x, ev.y, ev.p > 0
            kind = int(rng.integers(4))
            if kind == 0:
                f.create_dataset("events", data=rec[0])                                 # scalar compound
            elif kind == 1:
                f.create_dataset("events", data=rec.reshape(2, -1))
            elif kind == 2:
                f.create_dataset("events", shape=(10**9,), dtype=rec.dtype, chunks=(64,))
            else:
                odd = rec.astype([("timestamp", "<f8"), ("x", "<f4"), ("y", "<i2"), ("polarity", "<i1")])
                odd["timestamp"][int(rng.integers(len(odd)))] = _pick(rng, _NUMBERS)
                odd["polarity"][int(rng.integers(len(odd)))] = _pick(rng, (0, 1, 2, -1))
                f.create_dataset("events", data=odd)

    return _h5_bytes(build)


# --------------------------------------------------------------------------- cases
def _reader(name: str) -> Callable[[Path], Any]:
    from neuspike.formats import read_dat, read_events, read_spike_npz

    if name == "dat":
        return lambda p: read_dat(p, height=H, width=W)
    if name == "spike_npz":
        return read_spike_npz
    return read_events


def cases(name: str, n: int, seed: int, folder: Path) -> Iterator[tuple[str, str, Callable[[], Any]]]:
    """``n`` cases ``(label, file name, read)`` for reader ``name``; ``read()`` writes the file under
    ``folder`` and reads it."""
    rng = np.random.default_rng([seed, READERS.index(name)])
    seeds = seed_files(np.random.default_rng(seed))[name]
    read = _reader(name)
    ev = _events(np.random.default_rng(seed))

    def file_case(label: str, file_name: str, data: bytes, call: Callable[[Path], Any] = read):
        def run() -> Any:
            path = folder / file_name
            path.write_bytes(data)
            return call(path)
        return label, file_name, run

    for i in range(n):
        fname, data = seeds[i % len(seeds)]
        structural = rng.random() < 0.4
        if name == "dat":
            if structural:
                from neuspike.formats import read_dat

                start = _pick(rng, (0, 1, 3, 4, -1, 5, 1.5, 2.0, float("inf"), float("nan"), None, "1", True,
                                    np.int64(2), 10**30))
                stop = _pick(rng, (None, 0, 2, 4, 5, -1, 3.5, float("inf"), "x", np.uint8(3)))
                yield file_case(f"dat args start={start!r} stop={stop!r}", fname, data,
                                lambda p, a=start, b=stop: read_dat(p, height=H, width=W, start=a, stop=b))
            else:
                yield file_case(f"dat mutation {i}", fname, mutate(data, rng))
        elif name in ("spike_npz", "events_npz"):
            if structural:
                if name == "spike_npz":
                    arrays = dict(planes=rng.random((4, H, W)) < 0.3, plane_rate_hz=np.float64(20_000),
                                  start_s=np.float64(0), gain=np.float64(0.25), meta_json=np.array("{}"))
                    for key in ("plane_rate_hz", "start_s", "gain"):
                        if rng.random() < 0.3:
                            arrays[key] = np.asarray(_pick(rng, _NUMBERS + ("abc", (1, 2))))
                else:
                    arrays = dict(t_s=ev.t_s, x=ev.x, y=ev.y, p=ev.p, width=np.int64(W), height=np.int64(H))
                    for key in ("width", "height"):
                        if rng.random() < 0.3:
                            arrays[key] = np.asarray(_pick(rng, _NUMBERS + ("abc", (3, 4))))
                kind = int(rng.integers(10))
                if kind == 0:
                    key = "planes" if name == "spike_npz" else "t_s"
                    shape = _pick(rng, ((10**6, 1000, 1000), (2**40,), (10**12, 2, 2)))
                    blob = _npz_bytes(**{k: v for k, v in arrays.items() if k != key})
                    blob = _zip_with_member(blob, key, _huge_npy_header(shape))
                    yield file_case(f"{name} header declares {shape}", fname, blob)
                elif kind == 1:
                    yield file_case(f"{name} plain .npy", fname, _npy_bytes(next(iter(arrays.values()))))
                else:
                    yield file_case(f"{name} structure {i}", fname, _odd_npz(rng, arrays, rng.random() < 0.5))
            else:
                yield file_case(f"{name} mutation {i}", fname, mutate(data, rng, head=256))
        elif name == "h5":
            if structural:
                yield file_case(f"h5 structure {i}", fname, _odd_h5(rng, ev))
            else:
                yield file_case(f"h5 mutation {i}", fname, mutate(data, rng, head=4096))
        elif name == "txt":
            text = gzip.decompress(data) if fname.endswith(".gz") else data
            if structural:
                body = mutate_text(text.decode(), rng).encode("utf-8", "surrogatepass")
            else:
                body = mutate(text, rng, head=64)
            yield file_case(f"txt mutation {i} ({fname})", fname,
                            gzip.compress(body, mtime=0) if fname.endswith(".gz") and rng.random() < 0.8 else body)
        elif name == "aedat4":
            yield file_case(f"aedat4 mutation {i}", fname, mutate(data, rng, head=900))
        else:
            raise ValueError(f"unknown reader {name!r}")


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _zip_with_member(archive: bytes, key: str, member: bytes) -> bytes:
    import zipfile

    buf = io.BytesIO(archive)
    with zipfile.ZipFile(buf, "a") as z:
        z.writestr(f"{key}.npy", member)
    return buf.getvalue()


# --------------------------------------------------------------------------- verdicts
def outcome(run: Callable[[], Any], file_name: str) -> str:
    """``"ok"``, ``"typed"`` or ``"untyped: <type>: <message>"`` for one case reading ``file_name``."""
    try:
        value = run()
    except NeuSpikeError as exc:
        # a file's fault names the file; an argument's fault (InputError) names the argument
        if isinstance(exc, ValueError) and (file_name in str(exc) or isinstance(exc, InputError)):
            return "typed"
        return f"untyped: {type(exc).__name__} (not a ValueError naming the file): {str(exc)[:200]}"
    except Exception as exc:
        return f"untyped: {type(exc).__name__}: {str(exc)[:200]}"
    if isinstance(value, (EventStream, SpikeStream)):
        return "ok"
    if isinstance(value, np.ndarray) and value.dtype == np.bool_ and value.ndim == 3 and value.shape[1:] == (H, W):
        return "ok"
    return f"untyped: returned {type(value).__name__}"
