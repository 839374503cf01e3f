"""LeRobot's dataset layout (``codebase_version`` v3.0, the one lerobot 0.4 reads), written and read
with pyarrow alone.

Every lerobot release on the package index pins an older torch (0.4.4: ``torch<2.11``), ``packaging<26``
and ``wandb<0.25`` than this project's constraints, so lerobot cannot be installed beside rlgrasp; the
format is small enough to write directly:

    meta/info.json                                  fps, features (dtype, shape, names), totals
    meta/stats.json                                 min, max, mean, std, count, quantiles per feature
    meta/tasks.parquet                              the task strings (pandas' index) and their index
    meta/episodes/chunk-000/file-000.parquet        each episode's length and rows
    data/chunk-000/file-000.parquet                 one row per frame

Images are PNG bytes inside the data file (LeRobot's ``use_videos=False``), so no video codec is
needed on either side. tests/test_lerobot_dataset.py checks the files against LeRobot's own loader
where lerobot is installed.

A received dataset is data (``rlgrasp.received``): ``read_dataset`` refuses links, reads only the
parquet files of the layout above and only the columns ``meta/info.json`` declares, never opens a
path a row names (an image is read from its own bytes), decodes nothing but PNG, checks every column's
type and shape against the declaration, and writes nothing. Each refusal is one line.
"""

from __future__ import annotations

import io
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

CODEBASE_VERSION = "v3.0"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
DATA_FILE = re.compile(r"chunk-\d{3}/file-\d{3}\.parquet")
#: The columns LeRobot adds to every dataset.
INDEX_FEATURES: dict[str, dict[str, Any]] = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}
#: The feature dtypes read (``image``: PNG bytes of a height x width x channels uint8 array).
DTYPES = ("float32", "float64", "int64", "int32", "uint8", "bool", "image")
IMAGE_NAMES = ["height", "width", "channels"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
QUANTILES = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}


class LeRobotFormatError(ValueError):
    """A LeRobot dataset that cannot be read; the message is one line naming the key and value."""


def _pa() -> Any:
    """pyarrow, imported when a dataset is read or written: it is the ``lerobot`` extra's.

    Without pandas installed, ``import rlgrasp`` marks it absent (``None`` in ``sys.modules``), and
    pyarrow's compiled import of pandas takes that ``None`` for the module and fails on its first
    array; so its one look for pandas is made here, with the mark lifted."""
    try:
        import pyarrow as pa
        import pyarrow.parquet  # noqa: F401  (pa.parquet)
    except ImportError:
        raise LeRobotFormatError("LeRobot datasets need pyarrow: pip install -e '.[lerobot]'") from None
    if "pandas" in sys.modules and sys.modules["pandas"] is None:
        del sys.modules["pandas"]
        try:
            pa.array(np.zeros(1))  # pyarrow looks for pandas once, and remembers it is not there
        finally:
            sys.modules["pandas"] = None  # type: ignore[assignment]
    return pa


# --- writing ---------------------------------------------------------------------------------------


def write_dataset(
    root: Path,
    columns: dict[str, np.ndarray],
    features: dict[str, dict[str, Any]],
    episode: np.ndarray,
    fps: int,
    task: str,
    robot_type: str | None = None,
) -> None:
    """Write the dataset of ``columns`` (key -> an array of one row per frame, in its feature's dtype;
    an image feature's as height x width x channels uint8) into the new folder ``root``.
    ``episode`` is each frame's episode index, episodes contiguous and numbered from 0."""
    pa = _pa()
    n = len(episode)
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]]) if n else np.zeros(0, int)
    lengths = np.diff(np.r_[starts, n])
    frame_index = np.arange(n) - np.repeat(starts, lengths)
    columns = {
        **columns,
        "timestamp": (frame_index / fps).astype(np.float32),
        "frame_index": frame_index.astype(np.int64),
        "episode_index": episode.astype(np.int64),
        "index": np.arange(n, dtype=np.int64),
        "task_index": np.zeros(n, np.int64),
    }
    features = {**features, **INDEX_FEATURES}
    table = pa.table({key: _arrow_column(columns[key], ft) for key, ft in features.items()})
    (root / "data/chunk-000").mkdir(parents=True)
    (root / "meta/episodes/chunk-000").mkdir(parents=True)
    pa.parquet.write_table(table, root / DATA_PATH.format(chunk_index=0, file_index=0))
    _write_episodes(root, starts, lengths, task)
    _write_tasks(root, task)
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": robot_type,
        "total_episodes": len(starts),
        "total_frames": n,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": int(fps),
        "splits": {"train": f"0:{len(starts)}"},
        "data_path": DATA_PATH,
        "video_path": None,
        "features": features,
    }
    (root / "meta/info.json").write_text(json.dumps(info, indent=4))
    stats = {key: _stats(columns[key], ft) for key, ft in features.items()}
    (root / "meta/stats.json").write_text(json.dumps(stats, indent=4))


def _arrow_column(values: np.ndarray, feature: dict[str, Any]) -> Any:
    """One feature's column as LeRobot's writer lays it out: a scalar for shape [1], PNG structs for
    images, (nested) fixed-size lists otherwise."""
    pa = _pa()
    if feature["dtype"] == "image":
        pngs = [_png(frame) for frame in values]
        return pa.StructArray.from_arrays(
            [pa.array(pngs, pa.binary()), pa.array([None] * len(pngs), pa.string())], names=["bytes", "path"]
        )
    shape = list(feature["shape"])
    array = pa.array(np.ascontiguousarray(values).reshape(-1))
    if shape == [1]:
        return array
    for size in reversed(shape):
        array = pa.FixedSizeListArray.from_arrays(array, size)
    return array


def _png(frame: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    image = frame[..., 0] if frame.shape[-1] == 1 else frame
    Image.fromarray(np.ascontiguousarray(image)).save(buffer, format="PNG")
    return buffer.getvalue()


def _write_episodes(root: Path, starts: np.ndarray, lengths: np.ndarray, task: str) -> None:
    pa = _pa()
    n = len(starts)
    zeros = [0] * n
    table = pa.table(
        {
            "episode_index": pa.array(range(n), pa.int64()),
            "tasks": pa.array([[task]] * n, pa.list_(pa.string())),
            "length": pa.array(lengths, pa.int64()),
            "data/chunk_index": pa.array(zeros, pa.int64()),
            "data/file_index": pa.array(zeros, pa.int64()),
            "dataset_from_index": pa.array(starts, pa.int64()),
            "dataset_to_index": pa.array(starts + lengths, pa.int64()),
            "meta/episodes/chunk_index": pa.array(zeros, pa.int64()),
            "meta/episodes/file_index": pa.array(zeros, pa.int64()),
        }
    )
    pa.parquet.write_table(table, root / EPISODES_PATH.format(chunk_index=0, file_index=0))


def _write_tasks(root: Path, task: str) -> None:
    """``meta/tasks.parquet`` as pandas writes a frame indexed by the task string (LeRobot reads it
    with ``pandas.read_parquet`` and looks a task up by its index)."""
    pa = _pa()
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": None,
                "field_name": "__index_level_0__",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    schema = pa.schema([("task_index", pa.int64()), ("__index_level_0__", pa.string())])
    table = pa.table({"task_index": [0], "__index_level_0__": [task]}, schema=schema)
    table = table.replace_schema_metadata({"pandas": json.dumps(pandas_meta)})
    pa.parquet.write_table(table, root / "meta/tasks.parquet")


def _stats(values: np.ndarray, feature: dict[str, Any]) -> dict[str, list[Any]]:
    """LeRobot's statistics of one feature: per element, an image's per channel in [0, 1] (shape
    channels x 1 x 1, as LeRobot's normalization reads them)."""
    x = values.astype(np.float64)
    if feature["dtype"] == "image":
        x = x.reshape(len(x), -1, x.shape[-1]) / 255.0  # frames, pixels, channels
        axes: tuple[int, ...] = (0, 1)
    else:
        x = x.reshape(len(x), -1) if list(feature["shape"]) != [1] else x.reshape(-1, 1)
        axes = (0,)
    if not len(x):
        return {}

    def shaped(v: np.ndarray) -> list[Any]:
        return v.reshape(-1, 1, 1).tolist() if feature["dtype"] == "image" else v.reshape(-1).tolist()

    out = {
        "min": shaped(x.min(axis=axes)),
        "max": shaped(x.max(axis=axes)),
        "mean": shaped(x.mean(axis=axes)),
        "std": shaped(x.std(axis=axes)),
        "count": [len(values)],
    }
    out.update({name: shaped(np.quantile(x, q, axis=axes)) for name, q in QUANTILES.items()})
    return out


# --- reading ---------------------------------------------------------------------------------------


def read_info(root: Path, source: str) -> dict[str, Any]:
    """``meta/info.json`` of ``root``, its version, fps and every feature's dtype and shape checked."""
    path = root / "meta/info.json"
    if not path.is_file():
        raise LeRobotFormatError(f"{source}: {root} has no meta/info.json (not a LeRobot dataset folder)")
    try:
        info = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise LeRobotFormatError(f"{source}: unreadable meta/info.json ({type(exc).__name__})") from None
    if not isinstance(info, dict):
        raise LeRobotFormatError(f"{source}: refused: meta/info.json holds a {type(info).__name__}")
    version = info.get("codebase_version")
    if version != CODEBASE_VERSION:
        raise LeRobotFormatError(
            f"{source}: refused: meta/info.json: codebase_version={version!r} (read: {CODEBASE_VERSION!r}, "
            "lerobot 0.4's; convert older datasets with lerobot's convert_dataset_v21_to_v30)"
        )
    fps = info.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < fps < 1e6:
        raise LeRobotFormatError(f"{source}: refused: meta/info.json: fps={fps!r} (a positive number)")
    features = info.get("features")
    if not isinstance(features, dict) or not features:
        raise LeRobotFormatError(f"{source}: refused: meta/info.json: features={features!r} (a mapping)")
    for key, feature in features.items():
        if not isinstance(feature, dict) or not isinstance(feature.get("dtype"), str):
            raise LeRobotFormatError(
                f"{source}: refused: meta/info.json: features[{key!r}]={feature!r} (a mapping of dtype, "
                "shape, names)"
            )
    for key, feature in INDEX_FEATURES.items():
        if features.get(key, {}).get("dtype") != feature["dtype"]:
            raise LeRobotFormatError(
                f"{source}: refused: meta/info.json: features[{key!r}] is {features.get(key)!r} "
                f"(LeRobot's {key} is {feature['dtype']} of shape [1])"
            )
    return info


def _check_feature(key: str, feature: dict[str, Any], source: str) -> None:
    """A feature to be read: a dtype of ``DTYPES`` and a shape of positive sizes (others, a video or a
    language string, are refused only when read)."""
    where = f"{source}: refused: meta/info.json: features[{key!r}]"
    dtype, shape = feature.get("dtype"), feature.get("shape")
    if dtype == "video":
        raise LeRobotFormatError(
            f"{where}.dtype='video' (allowed: {', '.join(DTYPES)}; no video decoder is read here: "
            "write the dataset with use_videos=False)"
        )
    if dtype not in DTYPES:
        raise LeRobotFormatError(f"{where}.dtype={dtype!r} (allowed: {', '.join(DTYPES)})")
    sizes_ok = isinstance(shape, list) and all(type(n) is int and 0 < n <= 1 << 16 for n in shape)
    if not sizes_ok or not 1 <= len(shape) <= 4 or (dtype == "image" and len(shape) != 3):
        allowed = (
            "3 positive sizes, height x width x channels" if dtype == "image" else "1 to 4 positive sizes"
        )
        raise LeRobotFormatError(f"{where}.shape={shape!r} (allowed: {allowed})")
    if dtype == "image" and shape[2] not in (1, 3):
        raise LeRobotFormatError(f"{where}.shape={shape!r} (an image has 1 or 3 channels)")


def read_dataset(root: Path, source: str, keys: list[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """``meta/info.json`` and the columns ``keys`` (those of them declared, and LeRobot's index
    columns) of the dataset at ``root``, each an array of one row per frame in its declared dtype and
    shape (an image's height x width x channels)."""
    pa = _pa()
    info = read_info(root, source)
    features = info["features"]
    wanted = [k for k in dict.fromkeys([*keys, *INDEX_FEATURES]) if k in features]
    for key in wanted:
        _check_feature(key, features[key], source)
    files = sorted((root / "data").glob("*/*.parquet")) if (root / "data").is_dir() else []
    if not files:
        raise LeRobotFormatError(f"{source}: {root} has no data/chunk-*/file-*.parquet (no frames)")
    tables = []
    for path in files:
        relative = path.relative_to(root / "data").as_posix()
        if not DATA_FILE.fullmatch(relative):
            raise LeRobotFormatError(
                f"{source}: refused: data/{relative} is not a chunk-NNN/file-NNN.parquet"
            )
        try:
            schema = pa.parquet.read_schema(path)
            missing = [k for k in wanted if k not in schema.names]
            if missing:
                raise LeRobotFormatError(f"{source}: refused: data/{relative} has no column {missing[0]!r}")
            tables.append(pa.parquet.read_table(path, columns=wanted))
        except (pa.ArrowException, OSError) as exc:
            raise LeRobotFormatError(f"{source}: unreadable data/{relative} ({type(exc).__name__})") from None
    table = pa.concat_tables(tables)
    total = info.get("total_frames")
    if total != table.num_rows:
        raise LeRobotFormatError(
            f"{source}: refused: meta/info.json: total_frames={total!r}, the data files hold {table.num_rows}"
        )
    columns = {key: _column(table.column(key), key, features[key], source) for key in wanted}
    return info, columns


def _column(column: Any, key: str, feature: dict[str, Any], source: str) -> np.ndarray:
    """One column as a numpy array of its declared dtype and shape; anything else is refused."""
    where = f"{source}: refused: column {key!r}"
    array = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    if feature["dtype"] == "image":
        return _images(array, key, feature["shape"], source)
    shape = list(feature["shape"])
    dims = [] if shape == [1] and not _is_list(array.type) else shape  # LeRobot writes [1] as a scalar
    for size in dims:
        if not _is_list(array.type) or array.null_count:
            raise LeRobotFormatError(f"{where} is {array.type}, declared {feature['dtype']} of shape {shape}")
        lengths = array.value_lengths().to_numpy(zero_copy_only=False)
        if (lengths != size).any():
            raise LeRobotFormatError(
                f"{where}: a row of length {int(lengths[lengths != size][0])}, declared {size}"
            )
        array = array.flatten()
    if array.null_count or not _same_type(array.type, feature["dtype"]):
        raise LeRobotFormatError(f"{where} holds {array.type} values, declared {feature['dtype']}")
    values = array.to_numpy(zero_copy_only=False)
    return values.reshape(len(column), *shape)


def _is_list(kind: Any) -> bool:
    pa = _pa()
    return pa.types.is_list(kind) or pa.types.is_large_list(kind) or pa.types.is_fixed_size_list(kind)


def _same_type(kind: Any, dtype: str) -> bool:
    pa = _pa()
    want = {
        "float32": pa.float32(),
        "float64": pa.float64(),
        "int64": pa.int64(),
        "int32": pa.int32(),
        "uint8": pa.uint8(),
        "bool": pa.bool_(),
    }
    return kind == want[dtype]


def _images(array: Any, key: str, shape: list[int], source: str) -> np.ndarray:
    """PNG images from their own bytes (a row's ``path`` is never opened), each of the declared size."""
    from PIL import Image

    pa = _pa()
    if not pa.types.is_struct(array.type) or array.type.get_field_index("bytes") < 0:
        raise LeRobotFormatError(f"{source}: refused: column {key!r} is {array.type}, declared image")
    blobs = array.field("bytes").to_pylist()
    out = np.empty((len(blobs), *shape), np.uint8)
    for i, blob in enumerate(blobs):
        if not isinstance(blob, bytes) or not blob.startswith(PNG_MAGIC):
            raise LeRobotFormatError(
                f"{source}: refused: {key} of row {i} is not PNG bytes in the data file (images are read "
                "from the dataset's own bytes, never from a path)"
            )
        try:
            with Image.open(io.BytesIO(blob), formats=["PNG"]) as image:
                if image.size != (shape[1], shape[0]):
                    raise LeRobotFormatError(
                        f"{source}: refused: {key} of row {i} is {image.size[1]}x{image.size[0]}, declared "
                        f"{shape[0]}x{shape[1]}"
                    )
                pixels = np.asarray(image.convert("RGB" if shape[2] == 3 else "L"))
        except (OSError, ValueError, Image.DecompressionBombError) as exc:
            if isinstance(exc, LeRobotFormatError):
                raise
            raise LeRobotFormatError(f"{source}: refused: {key} of row {i}: {type(exc).__name__}") from None
        out[i] = pixels.reshape(shape)
    return out
