"""The table of environments, and everything derived from it.

:data:`ENVS` holds one :class:`EnvEntry` per environment: its registry name, the module whose
``parallel_env`` builds it, the Gymnasium id of each player's single-agent view and the backends
of its native vector env. Everything else that lists the environments reads this table:

- the Gymnasium ids (``gymnasium.make`` / ``gymnasium.make_vec``), registered by
  :func:`register_env`; :data:`GYM_IDS` maps each id to ``(module, agent)``;
- the ids with a native vector env on each backend (:func:`vector_ids`, :func:`torch_ids`);
- ``agents.registry`` (each trainable's Gymnasium id), the RLlib env names
  (``agents.rllib.envs``), the docs' env pages and the tests' parametrisations
  (:data:`ENV_NAMES`, :func:`load`; the tests of the Kalman-filter engine's conventions
  :func:`kalman_env_names` and :func:`kalman_gym_ids`).

Adding an environment is its module plus one :func:`register_env` call (a package of your own
calls it at import; the suite's own entries are at the end of this module):

>>> import fdia_env
>>> from fdia_env.registration import ENV_NAMES, GYM_IDS, get_env
>>> dict(get_env("sparse_attack_v0").views)
{'attacker': 'fdia_env/SparseAttack-v0'}
>>> GYM_IDS["fdia_env/SensorGameDefender-v0"]
('fdia_env.sensor_game_v0', 'defender')
>>> "fdia_v0" in ENV_NAMES
True
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType, ModuleType
from typing import Any

import gymnasium

AGENTS = ("attacker", "defender")
BACKENDS = ("numpy", "torch")
SINGLE_ENTRY_POINT = "fdia_env.envs.single_agent:make_single_agent"
VECTOR_ENTRY_POINT = "fdia_env.vector.env:make_vector"

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MODULE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")
_GYM_ID = re.compile(r"[\w.-]+/[\w.:-]+-v\d+")


@dataclass(frozen=True)
class EnvEntry:
    """One environment of the suite.

    Attributes:
        name: Registry name (``"sparse_attack_v0"``): the RLlib multi-agent env name and the
            ``--env`` of ``train.py``.
        module: Import path of the module whose ``parallel_env(**kwargs)`` builds the
            PettingZoo env (an :class:`~fdia_env.envs.parallel.FdiaParallelEnv`); it may also
            define ``default_opponent(parallel, agent)``.
        views: Learning agent (``"attacker"`` / ``"defender"``) → Gymnasium id of its
            single-agent view (``"namespace/Name-vN"``); empty for an env without views.
        backends: Backends of the native vector env (``gymnasium.make_vec(...,
            vectorization_mode="vector_entry_point", backend=...)``); empty when the env's
            models have no batched implementation (``make_vec`` then steps copies in
            ``SyncVectorEnv``).
        vector: The ``vector_entry_point`` of its native vector env (used when ``backends`` is
            not empty): the engine's :func:`fdia_env.vector.env.make_vector` by default.
        vector_views: The agents whose view has the native vector env (``None``, the default:
            every view; ``()``: none). A view without one is still registered, and
            ``make_vec`` steps its copies in ``SyncVectorEnv`` (``"sync"``/``"async"`` modes).
        view_kwargs: Agent → fixed options its view passes to ``parallel_env`` (the stealth
            env's defender view: ``{"defender": "threshold"}``, the env without them having no
            defender); a user's option of the same name overrides them.
        kalman: Whether the env runs the Kalman-filter engine (an ``FdiaParallelEnv``: a
            scenario, ``dynamics``, the ``phi``/``step`` infos, Φ in the render); False for an
            env of its own (the static stealthy attacker). Tests of the engine's conventions
            run on the entries with ``kalman`` set.
    """

    name: str
    module: str
    views: Mapping[str, str] = field(default_factory=dict)
    backends: tuple[str, ...] = BACKENDS
    kalman: bool = True
    vector: str = VECTOR_ENTRY_POINT
    vector_views: tuple[str, ...] | None = None
    view_kwargs: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ValueError(f"name must be a Python identifier, got {self.name!r}")
        if not isinstance(self.module, str) or not _MODULE.fullmatch(self.module):
            raise ValueError(f"module must be a dotted import path, got {self.module!r}")
        if not isinstance(self.views, Mapping):
            raise TypeError(f"views must be a mapping agent -> Gymnasium id, got {self.views!r}")
        for agent, env_id in self.views.items():
            if agent not in AGENTS:
                raise ValueError(f"views: agent must be one of {list(AGENTS)}, got {agent!r}")
            if not isinstance(env_id, str) or not _GYM_ID.fullmatch(env_id):
                raise ValueError(
                    f"views: the Gymnasium id of {agent!r} must read 'namespace/Name-vN', "
                    f"got {env_id!r}"
                )
        if len(set(self.views.values())) != len(self.views):
            raise ValueError(f"views: each agent needs its own Gymnasium id, got {self.views}")
        if not isinstance(self.backends, tuple) or not set(self.backends) <= set(BACKENDS):
            raise ValueError(f"backends must be a tuple of {list(BACKENDS)}, got {self.backends!r}")
        if not isinstance(self.vector, str) or not re.fullmatch(r"[\w.]+:\w+", self.vector):
            raise ValueError(f"vector must read 'module:function', got {self.vector!r}")
        if not isinstance(self.kalman, bool):
            raise TypeError(f"kalman must be a bool, got {self.kalman!r}")
        if "torch" in self.backends and "numpy" not in self.backends:
            raise ValueError("backends: the torch backend needs the numpy one (the reference)")
        if self.vector_views is not None:
            if not isinstance(self.vector_views, tuple) or not set(self.vector_views) <= set(
                self.views
            ):
                raise ValueError(
                    "vector_views must be None or a tuple of agents with a view "
                    f"{list(self.views)}, got {self.vector_views!r}"
                )
        if not isinstance(self.view_kwargs, Mapping) or not all(
            agent in self.views
            and isinstance(options, Mapping)
            and all(isinstance(k, str) for k in options)
            for agent, options in self.view_kwargs.items()
        ):
            raise ValueError(
                "view_kwargs must map agents with a view "
                f"{list(self.views)} to mappings of option names, got {self.view_kwargs!r}"
            )
        reserved = {"module", "agent"} & {k for o in self.view_kwargs.values() for k in o}
        if reserved:
            raise ValueError(f"view_kwargs: {sorted(reserved)} are set by the table itself")
        object.__setattr__(self, "views", MappingProxyType(dict(self.views)))
        object.__setattr__(
            self,
            "view_kwargs",
            MappingProxyType({a: MappingProxyType(dict(o)) for a, o in self.view_kwargs.items()}),
        )

    def has_vector(self, agent: str) -> bool:
        """Whether ``agent``'s view has the native vector env (on at least one backend)."""
        if agent not in self.views or not self.backends:
            return False
        return self.vector_views is None or agent in self.vector_views

    def __hash__(self) -> int:
        views = tuple(self.views.items())
        options = tuple((a, tuple(sorted(o.items()))) for a, o in self.view_kwargs.items())
        return hash(
            (
                self.name,
                self.module,
                views,
                self.backends,
                self.kalman,
                self.vector,
                self.vector_views,
                options,
            )
        )


_ENVS: dict[str, EnvEntry] = {}
ENVS: Mapping[str, EnvEntry] = MappingProxyType(_ENVS)
"""Registry name → :class:`EnvEntry`, in registration order (read-only: :func:`register_env`)."""


class _LiveIndex(Mapping):
    """A read-only mapping recomputed from the table at each access."""

    def __init__(self, build: Callable[[], dict[str, Any]], doc: str) -> None:
        self._build = build
        self.__doc__ = doc

    def __getitem__(self, key: str) -> Any:
        return self._build()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._build())

    def __len__(self) -> int:
        return len(self._build())

    def __repr__(self) -> str:
        return repr(self._build())


class _LiveNames(Sequence):
    """The registry names, recomputed from the table at each access."""

    def __getitem__(self, index: Any) -> Any:
        return tuple(_ENVS)[index]

    def __len__(self) -> int:
        return len(_ENVS)

    def __contains__(self, name: object) -> bool:
        return name in _ENVS

    def __repr__(self) -> str:
        return repr(tuple(_ENVS))


ENV_NAMES: Sequence[str] = _LiveNames()
"""The registry names of :data:`ENVS`, in registration order (follows the table)."""


def kalman_env_names() -> list[str]:
    """The registry names of the entries that run the Kalman-filter engine (``kalman``)."""
    return [name for name, entry in _ENVS.items() if entry.kalman]


def kalman_gym_ids() -> list[str]:
    """The Gymnasium ids of the views of the entries that run the Kalman-filter engine."""
    return [i for entry in _ENVS.values() if entry.kalman for i in entry.views.values()]


GYM_IDS: Mapping[str, tuple[str, str]] = _LiveIndex(
    lambda: {
        env_id: (entry.module, agent)
        for entry in _ENVS.values()
        for agent, env_id in entry.views.items()
    },
    "Gymnasium id → (module, learning agent) of every view in :data:`ENVS` (follows the table).",
)


def get_env(name: str) -> EnvEntry:
    """The entry of registry name ``name``.

    Raises:
        ValueError: For a name not in the table (listing the names that are).
    """
    if name not in _ENVS:
        raise ValueError(f"unknown env {name!r}; registered envs: {', '.join(_ENVS)}")
    return _ENVS[name]


def load(name: str) -> ModuleType:
    """The module of registry name ``name`` (imported)."""
    return importlib.import_module(get_env(name).module)


def vector_ids(backend: str = "numpy") -> tuple[str, ...]:
    """The Gymnasium ids with a native vector env on ``backend`` (``"numpy"`` or ``"torch"``)."""
    return tuple(
        env_id
        for e in _ENVS.values()
        if backend in e.backends
        for agent, env_id in e.views.items()
        if e.has_vector(agent)
    )


def torch_ids() -> tuple[str, ...]:
    """The Gymnasium ids whose native vector env runs on torch (``backend="torch"``)."""
    return vector_ids("torch")


def register_env(entry: EnvEntry) -> EnvEntry:
    """Add ``entry`` to :data:`ENVS` and register its Gymnasium ids (single and vector).

    Registering an entry equal to one already there does nothing.

    Raises:
        TypeError: For something other than an :class:`EnvEntry`.
        ValueError: For a name or module already registered with other settings, or a
            Gymnasium id already taken (by another entry or by another package).
    """
    if not isinstance(entry, EnvEntry):
        raise TypeError(f"entry must be an EnvEntry, got {type(entry).__name__}")
    old = _ENVS.get(entry.name)
    if old is not None and old != entry:
        raise ValueError(f"env {entry.name!r} is already registered as {old}")
    twin = next((e.name for e in _ENVS.values() if e.module == entry.module), entry.name)
    if twin != entry.name:
        raise ValueError(f"module {entry.module!r} is already registered as env {twin!r}")
    for env_id in entry.views.values():
        spec = gymnasium.registry.get(env_id)
        if spec is not None and spec.kwargs.get("module") != entry.module:
            raise ValueError(f"Gymnasium id {env_id!r} is already registered ({spec.entry_point})")
        other = GYM_IDS.get(env_id)
        if other is not None and other[0] != entry.module:
            raise ValueError(f"Gymnasium id {env_id!r} is already the view of {other[0]}")
    _ENVS[entry.name] = entry
    _register_gym_ids(entry)
    return entry


def view_kwargs(module: str, agent: str) -> dict[str, Any]:
    """The fixed options of the view of ``agent`` on the env of ``module`` (``{}`` if none).

    :func:`fdia_env.envs.single_agent.make_single_agent` applies them, so a view built from
    ``(module, agent)`` (:data:`GYM_IDS`) is the one ``gymnasium.make`` gives.
    """
    if not isinstance(agent, str):  # the caller's check names a bad agent; none has options
        return {}
    for entry in _ENVS.values():
        if entry.module == module:
            return dict(entry.view_kwargs.get(agent, {}))
    return {}


def register_envs() -> None:
    """Register the Gymnasium ids of every entry of :data:`ENVS` (idempotent)."""
    for entry in _ENVS.values():
        _register_gym_ids(entry)


def _register_gym_ids(entry: EnvEntry) -> None:
    for agent, env_id in entry.views.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point=SINGLE_ENTRY_POINT,
            vector_entry_point=entry.vector if entry.has_vector(agent) else None,
            kwargs={"module": entry.module, "agent": agent, **entry.view_kwargs.get(agent, {})},
        )


for _entry in (
    EnvEntry(
        "sparse_attack_v0", "fdia_env.sparse_attack_v0", {"attacker": "fdia_env/SparseAttack-v0"}
    ),
    EnvEntry(
        "covariance_attack_v0",
        "fdia_env.covariance_attack_v0",
        {"attacker": "fdia_env/CovarianceAttack-v0"},
    ),
    EnvEntry(  # action="sequential": fdia_env.vector.sequential_game (both views)
        "sensor_game_v0",
        "fdia_env.sensor_game_v0",
        {
            "attacker": "fdia_env/SensorGameAttacker-v0",
            "defender": "fdia_env/SensorGameDefender-v0",
        },
    ),
    EnvEntry(
        "detection_game_v0",
        "fdia_env.detection_game_v0",
        {"defender": "fdia_env/DetectionDefender-v0", "attacker": "fdia_env/DetectionAttacker-v0"},
    ),
    EnvEntry("fdia_v0", "fdia_env.fdia_v0"),
    EnvEntry(  # sparse_attack_v0 with the sequential format the default above 16 sensors
        "sparse_attack_v1", "fdia_env.sparse_attack_v1", {"attacker": "fdia_env/SparseAttack-v1"}
    ),
    EnvEntry(  # sparse_attack_v1 with the plan-first order the sequential format's default
        "sparse_attack_v2", "fdia_env.sparse_attack_v2", {"attacker": "fdia_env/SparseAttack-v2"}
    ),
    EnvEntry(
        "stealth_attack_v0",
        "fdia_env.stealth.stealth_attack_v0",
        {"attacker": "fdia_env/StealthAttack-v0", "defender": "fdia_env/StealthDefender-v0"},
        backends=("numpy", "torch"),
        kalman=False,
        vector="fdia_env.stealth.vector:make_vector",
        vector_views=("attacker",),  # the defender's view: copies in SyncVectorEnv
        view_kwargs={"defender": {"defender": "threshold"}},
    ),
    EnvEntry(
        "stealth_dynamic_v0",
        "fdia_env.stealth.stealth_dynamic_v0",
        {
            "attacker": "fdia_env/StealthDynamic-v0",
            "defender": "fdia_env/StealthDynamicDefender-v0",
        },
        backends=("numpy", "torch"),
        kalman=False,
        vector="fdia_env.stealth.dynamic_vector:make_vector",
        vector_views=("attacker",),  # the defender's view: copies in SyncVectorEnv
        view_kwargs={"defender": {"defender": "threshold"}},
    ),
):
    register_env(_entry)
