"""The stored references and payoffs are checked when read: digests in the code, entry forms."""

from __future__ import annotations

import copy
import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdia_env import scenarios, tasks
from fdia_env.tasks import digests, payoffs
from fdia_env.tasks.stored import StoredDataError, check_references

PACKAGE = Path(tasks.__file__).resolve().parent
PRISTINE = (PACKAGE / "references.json").read_bytes()
TASK = "sparse/ch4-position-v0"


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.fixture
def references(tmp_path, monkeypatch):
    """Install a references.json (its text; ``trusted``: its digest recorded) in place of ours."""

    def install(data: dict, trusted: bool = False) -> Path:
        path = tmp_path / "references.json"
        text = json.dumps(data, indent=1).encode()
        path.write_bytes(text)
        monkeypatch.setattr(tasks, "REFERENCES_PATH", path)
        if trusted:
            monkeypatch.setattr(digests, "REFERENCES", sha(text))
        tasks.stored_references.cache_clear()
        tasks._tasks.cache_clear()
        return path

    yield install
    tasks.stored_references.cache_clear()
    tasks._tasks.cache_clear()


def pristine() -> dict:
    return json.loads(PRISTINE)


def test_the_recorded_digests_are_those_of_the_stored_files():
    """Fails when references.json, payoffs.json or a payoff file is edited by hand."""
    assert digests.REFERENCES == sha(PRISTINE)
    assert digests.PAYOFF_MANIFEST == sha((PACKAGE / "payoffs.json").read_bytes())
    listed = json.loads((PACKAGE / "payoffs.json").read_text())
    assert sorted(digests.PAYOFF_FILES) == sorted(listed)
    for name, digest in digests.PAYOFF_FILES.items():
        data = (PACKAGE / "payoffs" / name).read_bytes()
        assert digest == sha(data) == listed[name]["sha256"]


def test_an_edited_optimum_is_refused_naming_the_file(references):
    data = pristine()
    # the optimum at which SFS (the optimum itself) would score 2.99 normalised
    lo, sfs = data[TASK]["random"]["mean"], data[TASK]["heuristics"]["SFS"]
    data[TASK]["optimum"]["value"] = lo + (sfs - lo) / 2.99
    path = references(data)
    with pytest.raises(StoredDataError, match=r"references\.json: SHA-256 .* not the one"):
        tasks.get(TASK)
    with pytest.raises(StoredDataError, match=r"references\.json"):
        tasks.names()
    # what the digest prevents: the same file, trusted, rescales the score
    edited = check_references(path, path.read_bytes(), None)
    refs = tasks.References.from_dict(edited[TASK])
    assert refs.normalise(sfs) == pytest.approx(2.99, rel=1e-12)


def test_the_stored_references_load_when_unchanged(references):
    references(json.loads(PRISTINE), trusted=True)
    assert tasks.get(TASK).references.optimum.value == pristine()[TASK]["optimum"]["value"]


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        (("optimum", "value"), math.nan, r"optimum\.value: must be a finite number, got nan"),
        (("random", "mean"), math.inf, r"random\.mean: must be a finite number, got inf"),
        (("heuristics", "SFS"), -math.inf, r"heuristics\['SFS'\]: must be a finite number"),
        (("game_value",), math.nan, r"game_value: must be a finite number"),
        (("optimum", "value"), "0.03", r"optimum\.value: must be a number, got str"),
        (("optimum", "certified"), 1, r"optimum\.certified: must be true or false"),
        (("objective",), "trace2", r"objective must be one of"),
    ],
)
def test_a_bad_reference_value_names_the_file_entry_and_key(references, key, value, message):
    data = pristine()
    node = data[TASK]
    for k in key[:-1]:
        node = node[k]
    node[key[-1]] = value
    references(data, trusted=True)
    with pytest.raises(StoredDataError, match=rf"references\.json: entry '{TASK}'.*{message}"):
        tasks.get(TASK)


@pytest.mark.parametrize(
    ("key", "message"),
    [
        (("optimum",), r"missing key\(s\) 'optimum'"),
        (("random", "mean"), r"random: missing key\(s\) 'mean'"),
        (("optimum", "bound"), r"optimum: missing key\(s\) 'bound'"),
        (("date",), r"missing key\(s\) 'date'"),
    ],
)
def test_a_missing_reference_key_names_the_file_entry_and_key(references, key, message):
    data = pristine()
    node = data[TASK]
    for k in key[:-1]:
        node = node[k]
    del node[key[-1]]
    references(data, trusted=True)
    with pytest.raises(StoredDataError, match=rf"references\.json: entry '{TASK}'.*{message}"):
        tasks.get(TASK)


@pytest.mark.parametrize("kind", ["missing", "a folder"])
def test_an_unreadable_references_file_is_refused_naming_it(references, kind):
    path = references(pristine())
    path.unlink()
    if kind == "a folder":
        path.mkdir()
    with pytest.raises(StoredDataError, match=rf"{path}: cannot be read"):
        tasks.get(TASK)


# ------------------------------------------------------------------------------ payoffs


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty payoff store in ``tmp_path`` (not this package's: its manifest is the root)."""
    monkeypatch.setattr(payoffs, "_folder", lambda: tmp_path)
    payoffs.manifest.cache_clear()
    yield tmp_path
    payoffs.manifest.cache_clear()


def _game():
    sc = scenarios.get("ch5-game")
    L = np.arange(49, dtype=np.float64).reshape(7, 7) / 7.0
    return sc, L


def _edit_manifest(folder: Path, edit) -> None:
    path = folder / payoffs.MANIFEST
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    payoffs.manifest.cache_clear()


@pytest.mark.parametrize("name", ["../../evil.npy", "/tmp/evil.npy", "sub/evil.npy", "..evil.npy"])
def test_a_payoff_name_that_leaves_its_folder_is_refused(store, tmp_path, name):
    sc, L = _game()
    stored = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    evil = 2.0 * L
    outside = (store / payoffs.FOLDER / name).resolve()
    if name.startswith("/"):
        outside = tmp_path / "evil.npy"
        name = str(outside)
    outside.parent.mkdir(parents=True, exist_ok=True)
    np.save(outside, evil, allow_pickle=False)

    def swap(data):
        entry = data.pop(stored.name)
        data[name] = {**entry, "sha256": sha(outside.read_bytes())}

    _edit_manifest(store, swap)
    with pytest.raises(StoredDataError, match=r"payoffs\.json: entry .*plain file name"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


def test_a_float32_payoff_is_reported_as_its_dtype(store):
    sc, L = _game()
    path = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    np.save(path, L.astype(np.float32), allow_pickle=False)
    _edit_manifest(store, lambda d: d[path.name].update(sha256=sha(path.read_bytes())))
    with pytest.raises(StoredDataError, match=r"dtype float32, expected float64"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


def test_a_payoff_of_another_shape_is_reported_as_its_shape(store):
    sc, L = _game()
    path = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    np.save(path, L[:6], allow_pickle=False)
    _edit_manifest(store, lambda d: d[path.name].update(sha256=sha(path.read_bytes())))
    with pytest.raises(StoredDataError, match=r"shape \(6, 7\), expected \(7, 7\)"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


@pytest.mark.parametrize("key", ["power", "fingerprint", "sha256", "scenario"])
def test_a_missing_payoff_key_names_the_manifest_entry_and_key(store, key):
    sc, L = _game()
    path = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    _edit_manifest(store, lambda d: d[path.name].pop(key))
    with pytest.raises(
        StoredDataError, match=rf"payoffs\.json: entry '{path.name}': missing key\(s\) '{key}'"
    ):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


def test_the_package_store_refuses_a_file_swapped_with_its_manifest(store, monkeypatch):
    """An edited manifest cannot vouch for a changed file: the digests in the code decide."""
    sc, L = _game()
    path = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    monkeypatch.setattr(payoffs, "PACKAGE", store)  # the store is treated as the package's
    man = (store / payoffs.MANIFEST).read_bytes()
    monkeypatch.setattr(digests, "PAYOFF_MANIFEST", sha(man))
    monkeypatch.setattr(digests, "PAYOFF_FILES", {path.name: sha(path.read_bytes())})
    payoffs.manifest.cache_clear()
    assert np.array_equal(payoffs.stored_payoff(sc, 100.0, "independent", None), L)
    np.save(path, 2.0 * L, allow_pickle=False)
    _edit_manifest(store, lambda d: d[path.name].update(sha256=sha(path.read_bytes())))
    with pytest.raises(StoredDataError, match=r"payoffs\.json: SHA-256 .* not the one recorded"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)
    monkeypatch.setattr(digests, "PAYOFF_MANIFEST", sha((store / payoffs.MANIFEST).read_bytes()))
    payoffs.manifest.cache_clear()
    with pytest.raises(StoredDataError, match=rf"{path.name}: SHA-256 .* not the one recorded"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


def test_the_package_payoff_digests_are_kept_by_the_payoff_command_only(tmp_path, monkeypatch):
    """``write_payoff`` on the package's store rewrites the digests module; elsewhere not."""
    from fdia_env.tasks import stored

    before = stored.DIGESTS_PATH.read_bytes()
    monkeypatch.setattr(payoffs, "_folder", lambda: tmp_path)
    payoffs.manifest.cache_clear()
    sc, L = _game()
    payoffs.write_payoff(L, sc, 100.0, "independent", None)
    payoffs.manifest.cache_clear()
    assert stored.DIGESTS_PATH.read_bytes() == before


# ------------------------------------------------------------------------------ properties

# a corruption: (task index, key path, new value or DELETE)
DELETE = object()
_PATHS = [
    ("objective",),
    ("metric",),
    ("random",),
    ("random", "mean"),
    ("random", "ci95"),
    ("random", "episodes"),
    ("random", "seed"),
    ("heuristics",),
    ("optimum",),
    ("optimum", "value"),
    ("optimum", "name"),
    ("optimum", "certified"),
    ("optimum", "bound"),
    ("optimum", "gap"),
    ("game_value",),
    ("solvers",),
    ("date",),
    ("seconds",),
    ("extra",),
]
_VALUES = st.one_of(
    st.just(DELETE),
    st.sampled_from([math.nan, math.inf, -math.inf, None, True, False, [], {}, "x", "", 0]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-3, 3),
    st.text(max_size=3),
    st.lists(st.integers(0, 2), max_size=2),
)


def _corrupt(data: dict, entry: str, key: tuple, value) -> None:
    node = data[entry]
    for k in key[:-1]:
        if not isinstance(node.get(k), dict):
            return
        node = node[k]
    if value is DELETE:
        node.pop(key[-1], None)
    else:
        node[key[-1]] = value


@settings(max_examples=60, deadline=None)
@given(
    entry=st.sampled_from(sorted(json.loads(PRISTINE))),
    key=st.sampled_from(_PATHS),
    value=_VALUES,
)
def test_a_corrupted_references_file_loads_pristine_or_raises_naming_it(entry, key, value):
    data = json.loads(PRISTINE)
    _corrupt(data, entry, key, value)
    text = json.dumps(data, indent=1, ensure_ascii=False).encode() + b"\n"
    path = Path("/stored/references.json")
    # with the digest recorded in the code: exactly the pristine data, or a refusal
    try:
        loaded = check_references(path, text, digests.REFERENCES)
    except StoredDataError as exc:
        assert str(exc).startswith(f"{path}:")
    else:
        assert text == PRISTINE and loaded == check_references(path, PRISTINE, None)
    # entries alone (a file whose digest matches): a task built from every entry, or a
    # refusal naming the file and the entry; never a KeyError, TypeError or a NaN reference
    try:
        loaded = check_references(path, text, sha(text))
        task = tasks._build(tasks.spec(entry), loaded[entry])
    except StoredDataError as exc:
        assert str(exc).startswith(f"{path}: entry {entry!r}") or (
            str(exc).startswith(f"{tasks.REFERENCES_PATH}: entry {entry!r}")
        )
    else:
        refs = task.references
        numbers = [refs.random.mean, refs.optimum.value, *refs.heuristics.values()]
        assert all(math.isfinite(v) for v in numbers)


_PAYOFF_KEYS = ["scenario", "power", "allocation", "max_subset_size", "fingerprint", "shape"]
_PAYOFF_KEYS += ["sha256", "extra"]


@settings(max_examples=40, deadline=None)
@given(
    key=st.sampled_from(_PAYOFF_KEYS),
    value=st.one_of(_VALUES, st.just([305, 304]), st.just([304, 305]), st.just("../x.npy")),
    rename=st.sampled_from([None, "../evil.npy", "/abs.npy", "a/b.npy", "x.txt", ""]),
)
def test_a_corrupted_payoff_manifest_loads_pristine_or_raises_naming_it(key, value, rename):
    from fdia_env.tasks.stored import check_payoff_manifest

    folder = PACKAGE / payoffs.FOLDER
    text = (PACKAGE / payoffs.MANIFEST).read_bytes()
    data = json.loads(text)
    name = next(iter(data))
    entry = copy.deepcopy(data[name])
    if value is DELETE:
        entry.pop(key, None)
    else:
        entry[key] = value
    bad = {rename if rename is not None else name: entry}
    bad_text = json.dumps(bad, indent=1).encode() + b"\n"
    path = PACKAGE / payoffs.MANIFEST
    try:  # with the digest recorded in the code: the pristine manifest, or a refusal
        loaded = check_payoff_manifest(path, folder, bad_text, digests.PAYOFF_MANIFEST)
    except StoredDataError as exc:
        assert str(exc).startswith(f"{path}:")
    else:
        assert bad_text == text and loaded == check_payoff_manifest(path, folder, text, None)
    try:  # entries alone: each file loads as stored, or a refusal naming the manifest or file
        loaded = check_payoff_manifest(path, folder, bad_text, None)
        for n, e in loaded.items():
            payoffs._load(PACKAGE, n, e)
    except StoredDataError as exc:
        assert str(exc).startswith((f"{path}:", f"stored payoff {folder}"))
    else:
        assert loaded[name]["shape"] == data[name]["shape"]
        assert loaded[name]["sha256"] == data[name]["sha256"]


def test_the_digests_module_is_what_the_commands_write(tmp_path, monkeypatch):
    from fdia_env.tasks import stored

    committed = stored.DIGESTS_PATH.read_text()
    monkeypatch.setattr(stored, "DIGESTS_PATH", tmp_path / "digests.py")
    stored.write_digests(PACKAGE / "references.json", PACKAGE / "payoffs.json", PACKAGE / "payoffs")
    assert (tmp_path / "digests.py").read_text() == committed


def test_compute_refuses_to_keep_the_entries_of_a_bad_file(tmp_path):
    """``write`` keeps the other tasks' entries only from a file that passes its checks."""
    from agents.bench.verify import write

    data = pristine()
    data[TASK]["optimum"]["value"] = math.nan
    path = tmp_path / "references.json"
    path.write_text(json.dumps(data))
    with pytest.raises(StoredDataError, match=rf"{path}: entry '{TASK}', optimum\.value"):
        write(["sparse/ch4-random-v0"], path=path)
    assert math.isnan(json.loads(path.read_text())[TASK]["optimum"]["value"])  # left as it was
