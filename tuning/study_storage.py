"""Where Optuna studies live: the storage URL (SQLite by default, PostgreSQL through
psycopg 3), opening it with the heartbeat and the retry of dead trials, and what a study
tunes (its identity), checked before a job writes anything.

Messages name the URL with its password masked.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any

import optuna
import sqlalchemy
from optuna.storages import RDBStorage

try:
    from optuna.storages import RetryHeartbeatStaleTrialCallback
except ImportError:  # optuna < 4.9 (pyproject allows >= 4.0)
    from optuna.storages import RetryFailedTrialCallback as RetryHeartbeatStaleTrialCallback

from envs.evaluation import Weights
from envs.space import NAMES
from twin.config import MachineConfig
from twin.config.loader import machine_identity
from twin.errors import ConfigError

__all__ = ["GRACE_S", "HEARTBEAT_S", "check_identity", "check_study", "default_storage",
           "masked", "open_storage", "storage_url", "study_identity"]

HEARTBEAT_S = 5
"""Heartbeat interval of a running trial (s)."""
GRACE_S = 20
"""A RUNNING trial whose heartbeat is older than this is declared dead (s)."""


def default_storage(out_dir: Path) -> str:
    """The default storage URL: ``sqlite:///<out_dir>/optuna.db``."""
    return f"sqlite:///{(Path(out_dir) / 'optuna.db').resolve()}"


def storage_url(url: str) -> str:
    """``url`` as SQLAlchemy takes it: a PostgreSQL URL without a driver
    (``postgresql://``, ``postgres://``) uses psycopg 3, the driver the project installs."""
    for bare in ("postgresql://", "postgres://"):
        if url.startswith(bare):
            return "postgresql+psycopg://" + url[len(bare):]
    return url


def masked(url: str) -> str:
    """``url`` with its password replaced by ``***`` (for messages)."""
    try:
        return sqlalchemy.engine.make_url(url).render_as_string(hide_password=True)
    except Exception:   # not even a URL: hide whatever sits between ':' and '@'
        head, at, tail = url.rpartition("@")
        if not at:
            return url
        scheme, _, user = head.partition("://")
        return f"{scheme}://{user.split(':', 1)[0]}:***@{tail}"


def _without_password(text: str, url: str) -> str:
    try:
        password = sqlalchemy.engine.make_url(url).password
    except Exception:
        password = None
    return text.replace(str(password), "***") if password else text


def open_storage(url: str, *, heartbeat_s: int = HEARTBEAT_S,
                 grace_s: int = GRACE_S) -> RDBStorage:
    """The study database at ``url`` with the heartbeat and the retry of dead trials.

    Raises
    ------
    ConfigError
        (field ``storage``) The URL is malformed, names a database driver that is not
        installed, or the server cannot be reached or refuses the credentials; the message
        names the URL with its password masked.
    """
    optuna.logging.set_verbosity(optuna.logging.WARNING)

    def create() -> RDBStorage:
        with warnings.catch_warnings():   # the heartbeat is "experimental" in optuna 5
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            return RDBStorage(storage_url(url), heartbeat_interval=heartbeat_s,
                              grace_period=grace_s,
                              heartbeat_stale_trial_callback=RetryHeartbeatStaleTrialCallback(
                                  max_retry=2),
                              engine_kwargs=_engine_options(url))

    try:
        if not storage_url(url).startswith("postgresql"):
            return create()
        # Workers started together on an empty database would all create Optuna's tables
        # (CREATE TYPE races: "duplicate key ... pg_type"): one at a time, under a lock of
        # the server's that ends with the session
        engine = sqlalchemy.create_engine(storage_url(url), **_engine_options(url))
        try:
            with engine.connect() as conn:
                conn.execute(sqlalchemy.text("SELECT pg_advisory_lock(:key)"),
                             {"key": _SCHEMA_LOCK})
                try:
                    return create()
                finally:
                    conn.execute(sqlalchemy.text("SELECT pg_advisory_unlock(:key)"),
                                 {"key": _SCHEMA_LOCK})
        finally:
            engine.dispose()
    except (sqlalchemy.exc.SQLAlchemyError, ImportError, ValueError, OSError) as exc:
        reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()
        reason = " ".join(line.strip() for line in reason[:3])
        raise ConfigError("storage", f"cannot open the study database {masked(url)}: "
                          f"{_without_password(reason, url)}") from None


_SCHEMA_LOCK = int.from_bytes(b"xy-twin!", "big") >> 1
"""PostgreSQL advisory lock held while a worker creates or checks the study tables."""


def _engine_options(url: str) -> dict[str, Any]:
    """A server that does not answer fails in seconds, not a TCP timeout's minutes."""
    if storage_url(url).startswith("postgresql+psycopg://"):
        return {"connect_args": {"connect_timeout": 10}, "pool_pre_ping": True}
    return {}


def study_identity(cfg: MachineConfig, belief: MachineConfig | None, program: str,
                   weights: Weights, max_cycle_time_increase: float | None = None
                   ) -> dict[str, Any]:
    """What a study tunes: machine and controller-model names and configuration hashes,
    program, cost weights, the cycle-time constraint (when there is one) and coordinates
    (stored with the study, checked on joining)."""
    belief = belief or cfg
    limit = {} if max_cycle_time_increase is None else {
        "max_cycle_time_increase": float(max_cycle_time_increase)}
    return {**limit, "machine": cfg.name,
            "machine_config_sha256": machine_identity(cfg)["config_sha256"],
            "controller_model": belief.name,
            "controller_model_config_sha256": machine_identity(belief)["config_sha256"],
            "program": program,
            "weights": {k: float(v) for k, v in dataclasses.asdict(weights).items()},
            "coordinates": list(NAMES)}


def check_identity(found: dict[str, Any] | None, identity: dict[str, Any] | None, name: str,
                    storage: RDBStorage) -> None:
    if identity is None or found is None or found == identity:
        return
    where = storage.engine.url.render_as_string(hide_password=True)
    differ = sorted(k for k in set(found) | set(identity) if found.get(k) != identity.get(k))
    raise ConfigError("study", f"study {name!r} in {where} tunes something else: "
                      + "; ".join(f"{k} is {found.get(k)!r} there, {identity.get(k)!r} here"
                                  for k in differ[:3]))


def check_study(url: str, name: str, identity: dict[str, Any]) -> None:
    """Before a job writes anything: the storage opens, and study ``name``, if it exists,
    tunes what ``identity`` says (``ConfigError`` otherwise; nothing is created)."""
    storage = open_storage(url)
    try:
        study_id = storage.get_study_id_from_name(name)
    except KeyError:
        return
    check_identity(storage.get_study_user_attrs(study_id).get("identity"), identity, name,
                    storage)
