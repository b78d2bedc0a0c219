"""Reading PyTorch weights files without PyTorch (and without running any code in them).

A ``torch.save`` file is a pickle whose tensors are stored beside it as raw little-endian
buffers. Two layouts exist and both are read here:

* the zip layout (PyTorch >= 1.6, what the project's ``save_weights`` writes): ``*/data.pkl``
  plus one entry ``*/data/<key>`` per storage;
* the legacy layout (the thesis author's ``netparams.dat``): several pickles one after the other
  -- a magic number, the protocol version, system information, the object, the list of storage
  keys -- followed by each storage as an 8-byte element count and its bytes.

The unpickler is restricted: it resolves only ``collections.OrderedDict``,
``torch._utils._rebuild_tensor_v2`` / ``_rebuild_parameter`` and the typed storage classes
(``torch.FloatStorage``, ...), each to a local stand-in; any other global, an unexpected
persistent id, a truncated buffer or a broken pickle raises :class:`NotATorchFile`. Tensors come
back as NumPy arrays (copies). This is what ``torch.load(..., weights_only=True)`` allows, read
without importing torch.
"""

from __future__ import annotations

import collections
import io
import os
import pickle
import zipfile

import numpy as np

__all__ = ["read_torch_file", "NotATorchFile"]

_LEGACY_MAGIC = 0x1950A86A20F9469CFC6C
_LEGACY_PROTOCOL = 1001

_STORAGE_DTYPES = {
    "FloatStorage": np.float32, "DoubleStorage": np.float64, "HalfStorage": np.float16,
    "LongStorage": np.int64, "IntStorage": np.int32, "ShortStorage": np.int16,
    "CharStorage": np.int8, "ByteStorage": np.uint8, "BoolStorage": np.bool_,
}


class NotATorchFile(Exception):
    """The bytes are not a PyTorch file of plain tensors, numbers and strings."""


class _StorageType:
    def __init__(self, name):
        self.name = name
        self.dtype = np.dtype(_STORAGE_DTYPES[name]).newbyteorder("<")


class _LazyTensor:
    """A tensor whose storage is read after the pickle (the legacy layout stores it there)."""

    def __init__(self, storage, offset, size, stride):
        self.storage, self.offset = storage, int(offset)
        self.size, self.stride = tuple(int(s) for s in size), tuple(int(s) for s in stride)


def _rebuild_tensor_v2(storage, storage_offset, size, stride, requires_grad=False,
                       backward_hooks=None, metadata=None):
    if not isinstance(storage, _StorageRef):
        raise NotATorchFile("a tensor without a storage")
    return _LazyTensor(storage, storage_offset, size, stride)


def _rebuild_parameter(data, requires_grad=False, backward_hooks=None):
    if not isinstance(data, _LazyTensor):
        raise NotATorchFile("a parameter without a tensor")
    return data


class _StorageRef:
    def __init__(self, key, dtype, numel):
        self.key, self.dtype, self.numel = str(key), dtype, int(numel)
        self.array: np.ndarray | None = None


_ALLOWED = {
    ("collections", "OrderedDict"): collections.OrderedDict,
    ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor_v2,
    ("torch._utils", "_rebuild_parameter"): _rebuild_parameter,
}


class _Unpickler(pickle.Unpickler):
    def __init__(self, fh, storages: dict):
        super().__init__(fh)
        self.storages = storages

    def find_class(self, module, name):
        if (module, name) in _ALLOWED:
            return _ALLOWED[(module, name)]
        if module == "torch" and name in _STORAGE_DTYPES:
            return _StorageType(name)
        raise NotATorchFile(f"the file refers to {module}.{name}")

    def persistent_load(self, pid):
        if (not isinstance(pid, tuple) or len(pid) < 5 or pid[0] != "storage"
                or not isinstance(pid[1], _StorageType)):
            raise NotATorchFile("an unknown persistent object")
        if len(pid) > 5 and pid[5] is not None:
            raise NotATorchFile("storage views are not supported")
        stype, key, numel = pid[1], str(pid[2]), int(pid[4])
        ref = self.storages.get(key)
        if ref is None:
            ref = self.storages[key] = _StorageRef(key, stype.dtype, numel)
        return ref


def _materialize(obj):
    if isinstance(obj, _LazyTensor):
        buf = obj.storage.array
        if buf is None:
            raise NotATorchFile("a tensor's data is missing")
        need = obj.offset + sum((s - 1) * st for s, st in zip(obj.size, obj.stride)) + 1 \
            if all(obj.size) else 0
        if need > len(buf) or obj.offset < 0 or min(obj.stride, default=0) < 0:
            raise NotATorchFile("a tensor reaches past its data")
        if not all(obj.size):
            return np.zeros(obj.size, dtype=buf.dtype.newbyteorder("="))
        item = buf.dtype.itemsize
        view = np.lib.stride_tricks.as_strided(buf[obj.offset:], shape=obj.size,
                                               strides=tuple(s * item for s in obj.stride))
        return np.array(view, dtype=buf.dtype.newbyteorder("="))
    if isinstance(obj, dict):
        return type(obj)((k, _materialize(v)) for k, v in obj.items()) \
            if isinstance(obj, collections.OrderedDict) else {k: _materialize(v)
                                                              for k, v in obj.items()}
    if isinstance(obj, list):
        return [_materialize(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(_materialize(v) for v in obj)
    return obj


def _read_zip(data: bytes):
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        names = zf.namelist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise NotATorchFile(f"a broken zip archive ({exc})") from None
    pkl = [n for n in names if n.endswith("/data.pkl") or n == "data.pkl"]
    if len(pkl) != 1:
        raise NotATorchFile("no data.pkl in the archive")
    prefix = pkl[0][:-len("data.pkl")]
    byteorder = prefix + "byteorder"
    try:
        if byteorder in names and zf.read(byteorder).strip() not in (b"little", b""):
            raise NotATorchFile("big-endian tensors are not supported")
        storages: dict = {}
        obj = _Unpickler(io.BytesIO(zf.read(pkl[0])), storages).load()
        for key, ref in storages.items():
            raw = zf.read(f"{prefix}data/{key}")
            if len(raw) < ref.numel * ref.dtype.itemsize:
                raise NotATorchFile("a tensor's data is cut short")
            ref.array = np.frombuffer(raw, dtype=ref.dtype, count=ref.numel)
    except NotATorchFile:
        raise
    except (KeyError, zipfile.BadZipFile, OSError, EOFError, ValueError, TypeError,
            pickle.UnpicklingError, AttributeError, IndexError, MemoryError) as exc:
        raise NotATorchFile(f"an unreadable archive ({type(exc).__name__})") from None
    return obj


def _read_legacy(data: bytes):
    fh = io.BytesIO(data)
    storages: dict = {}
    try:
        if pickle.load(fh) != _LEGACY_MAGIC:  # a plain int: nothing to resolve
            raise NotATorchFile("not a PyTorch file")
        if pickle.load(fh) != _LEGACY_PROTOCOL:
            raise NotATorchFile("an unknown PyTorch file version")
        info = _Unpickler(fh, storages).load()
        if not isinstance(info, dict) or not info.get("little_endian", True):
            raise NotATorchFile("big-endian tensors are not supported")
        obj = _Unpickler(fh, storages).load()
        keys = _Unpickler(fh, {}).load()
        if not isinstance(keys, list):
            raise NotATorchFile("no list of storages")
        for key in keys:
            ref = storages.get(str(key))
            head = fh.read(8)
            if ref is None or len(head) < 8:
                raise NotATorchFile("a storage is missing or cut short")
            numel = int.from_bytes(head, "little", signed=True)
            nbytes = numel * ref.dtype.itemsize
            raw = fh.read(nbytes) if 0 <= numel <= len(data) else b""
            if numel < ref.numel or len(raw) < nbytes:
                raise NotATorchFile("a tensor's data is cut short")
            ref.array = np.frombuffer(raw, dtype=ref.dtype, count=numel)
    except NotATorchFile:
        raise
    except (EOFError, ValueError, TypeError, pickle.UnpicklingError, AttributeError,
            IndexError, KeyError, OverflowError, MemoryError) as exc:
        raise NotATorchFile(f"an unreadable file ({type(exc).__name__})") from None
    return obj


def read_torch_file(path):
    """The object of a ``torch.save`` file, tensors as NumPy arrays; NotATorchFile otherwise.

    Only plain containers (dict, OrderedDict, list, tuple), numbers, strings and tensors are
    accepted (see the module docstring)."""
    with open(os.fspath(path), "rb") as fh:
        data = fh.read()
    if data[:2] == b"PK":
        obj = _read_zip(data)
    elif data[:1] == b"\x80":
        obj = _read_legacy(data)
    else:
        raise NotATorchFile("not a PyTorch file")
    return _materialize(obj)
