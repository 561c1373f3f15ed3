"""Shared behaviour of the command-line entry points: every user error is one line and exit 2.

An entry script is::

    @hydra.main(config_path="../configs", config_name="solve_grasp", version_base="1.3")
    @user_errors_exit_2
    def main(cfg): ...

    if __name__ == "__main__":
        run_cli(main, SolveGraspJobCfg)

:func:`run_cli` checks the command line before Hydra composes anything: the override syntax
(Hydra's own parser), group options (a file under ``configs/<group>/``), unknown keys, and the
type and range of every value, each element of a sweep included (``seed=0,1,2``), against the
job's settings dataclass. Anything Hydra still refuses before the job starts (a run folder that
cannot be made, say) is turned into one line and exit 2 as well. Inside the job,
:func:`user_errors_exit_2` turns a :class:`GraspnetError` into one line and exit 2, and an
:class:`InternalError` (a non-finite result) into one line and exit 1; any other exception is a
bug and keeps its traceback (exit 1).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import os
import sys
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from graspnet_torch.errors import ConfigError, GraspnetError, InternalError, Interrupted, say
from graspnet_torch.jobs.interrupt import exit_interrupted, interrupted, remembering_interrupts
from graspnet_torch.paths import configs_dir
from graspnet_torch.settings import Free, check_value, clip, lookup
from graspnet_torch.solver.config import RENAMED

__all__ = ["check_overrides", "compose_for_check", "container", "hydra_overrides", "robot_path_overrides", "run_cli",
           "switch_overrides", "user_errors_exit_2"]

T = TypeVar("T")

_job_started = False  # set once Hydra hands over to the job: errors after that are the job's


def user_errors_exit_2(fn: Callable[..., T]) -> Callable[..., T]:
    """Run ``fn``; a :class:`GraspnetError` prints ``error: <message>`` on stderr and exits 2, an
    :class:`InternalError` prints ``internal error: <message>`` and exits 1, an
    :class:`Interrupted` (Ctrl-C in a training) ``interrupted: <message>`` and exits 130, as any
    other Ctrl-C does with a one-line ``interrupted (Ctrl-C): ...``."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        global _job_started
        if interrupted():  # a Ctrl-C that a library swallowed while Hydra started the run: nothing written yet
            exit_interrupted(False)
        _job_started = True
        try:
            out = fn(*args, **kwargs)
        except GraspnetError as exc:
            say(f"error: {_one_line(exc)}")
            sys.exit(2)
        except InternalError as exc:
            say(f"internal error: {_one_line(exc)}")
            sys.exit(1)
        except Interrupted as exc:  # Ctrl-C in a job that kept its work (a training's state)
            say(f"interrupted: {_one_line(exc)}")
            sys.exit(130)
        except KeyboardInterrupt:  # Ctrl-C anywhere else in a job: what was written is whole (atomic writes)
            exit_interrupted(True)
        except Exception:
            if interrupted():  # a Ctrl-C that a library's clean-up turned into another exception
                exit_interrupted(True)
            raise
        if interrupted():  # a Ctrl-C that a library swallowed: the job ran on to its end
            exit_interrupted(True)
        return out

    return wrapper


def container(cfg: Any) -> dict:
    """A composed Hydra config as a plain dict, interpolations resolved; a bad interpolation is a
    :class:`ConfigError`."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        return OmegaConf.to_container(cfg, resolve=True)
    except OmegaConfBaseException as exc:
        raise ConfigError(f"cannot resolve the settings: {_one_line(exc)}") from None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return clip(text, 400) if text else type(exc).__name__


def _group_options(group: str) -> list[str] | None:
    folder = configs_dir() / group
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else None


def _values(override) -> Iterable[Any]:
    """The values of an override: one, or each element of a sweep (the first 10,000 of a range)."""
    from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep, RangeSweep

    value = override.value()
    if isinstance(value, ChoiceSweep):
        return value.list
    if isinstance(value, RangeSweep):
        return itertools.islice(override.sweep_iterator(), 10_000)
    if isinstance(value, IntervalSweep):  # only for optimising sweepers: check the bounds
        return [value.start, value.end]
    return [value]


def _has_interpolation(value: Any) -> bool:
    return isinstance(value, str) and "${" in value


def _hydra_args(argv: list[str]):
    """Hydra's own command-line parser, refusing unknown options (``--foo``) in one line instead of
    argparse's usage text."""
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()

    def refuse(message: str):
        raise ConfigError(f"{clip(message, 200)} (see --help)")

    parser.error = refuse  # argparse calls this for every mistake
    args, unknown = parser.parse_known_args(argv)
    if args.multirun and (args.cfg or args.info or args.shell_completion):
        raise ConfigError("-m (a sweep) cannot be combined with --cfg, --info or --shell-completion: drop -m to "
                          "see one job's settings")
    if args.config_name or args.config_path or args.config_dir:
        raise ConfigError("--config-name, --config-path and --config-dir are not supported: this script's settings "
                          "are configs/ with key=value overrides; your own problems go in problem=PATH")
    options = [a for a in unknown if a.startswith("-")]
    if options:
        raise ConfigError(f"unknown option '{clip(options[0], 60)}': settings are key=value; options are "
                          f"--help, --cfg job, -m (see --help)")
    if unknown:  # settings after an option: argparse (and so Hydra) takes only one run of them
        raise ConfigError(f"'{clip(unknown[0], 60)}' comes after an option: put options such as -m before the "
                          f"key=value settings")
    return args


def check_overrides(argv: list[str], schema: type) -> None:
    """Refuse, with one :class:`ConfigError` line, a command line that Hydra would refuse or
    that sets a key the job does not have or a value outside its type and range."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    args = _hydra_args(argv)
    from hydra.core.override_parser.overrides_parser import OverridesParser

    try:
        overrides = OverridesParser.create().parse_overrides(args.overrides)
    except (HydraException, OmegaConfBaseException, ValueError) as exc:  # ValueError: an int of 5000 digits
        raise ConfigError(f"cannot parse the command line: {_one_line(exc)}") from None
    for o in overrides:
        key = o.key_or_group
        if key == "hydra" or key.startswith(("hydra.", "hydra/")) or o.is_delete():
            continue
        options = _group_options(key) if "." not in key else None
        if options is not None:
            for v in _values(o):
                if v is None:
                    raise ConfigError(f"{key}=null: expected one of {', '.join(options)} (configs/{key}/)")
                if str(v) not in options:
                    raise ConfigError(f"unknown {key} '{clip(str(v), 80)}': expected one of {', '.join(options)} "
                                      f"(configs/{key}/)")
            continue
        found = lookup(schema, key)
        if found is None:
            group, _, name = key.partition(".")
            if group == "solver" and name in RENAMED:
                raise ConfigError(f"unknown setting '{key}' (now solver.{RENAMED[name]})")
            parent, _, _ = key.rpartition(".")
            scope = lookup(schema, parent) if parent else (schema, {})
            names = sorted(scope[0].__dataclass_fields__) if scope and hasattr(scope[0], "__dataclass_fields__") else []
            listed = f"settings{' of ' + parent if parent else ''}: {', '.join(names)}" if names else "see --cfg job"
            raise ConfigError(f"unknown setting '{clip(key, 80)}' ({listed})")
        tp, meta = found
        if tp is Free:
            continue
        for v in _values(o):
            if not _has_interpolation(v):
                check_value(tp, meta, v, key)


MAX_CHECKED_JOBS = 256  # a sweep's first jobs composed and checked before it starts


def compose_for_check(config_name: str, argv: list[str]) -> list[tuple[dict, str]]:
    """The configs Hydra will compose, as plain dicts, each with its run folder: one for a single
    run, one per job of a ``-m`` sweep (its first :data:`MAX_CHECKED_JOBS`); none for ``--cfg``,
    ``--help`` and the like."""
    from hydra import compose, initialize_config_dir
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    args = _hydra_args(argv)
    if args.cfg or args.help or args.hydra_help or args.info or args.shell_completion or args.experimental_rerun:
        return []
    if args.multirun:
        parsed = OverridesParser.create().parse_overrides(args.overrides)
        jobs = [job for batch in BasicSweeper.split_arguments(parsed, MAX_CHECKED_JOBS) for job in batch]
        jobs = jobs[:MAX_CHECKED_JOBS]
    else:
        jobs = [args.overrides]
    out = []
    try:
        with initialize_config_dir(config_dir=str(configs_dir()), version_base="1.3", job_name=config_name):
            for overrides in jobs:
                cfg = compose(config_name=config_name, overrides=overrides, return_hydra_config=True)
                key = "hydra.sweep.dir" if args.multirun else "hydra.run.dir"
                out.append((container(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"])),
                            str(OmegaConf.select(cfg, key))))
    except (ValueError, TypeError, KeyError) as exc:  # Hydra raises these for some malformed overrides
        raise ConfigError(f"cannot compose the settings: {_one_line(exc)}") from None
    return out


def _is_robot_path(value: str) -> bool:
    return value.endswith((".yaml", ".yml")) or os.sep in value or "/" in value


def robot_path_overrides(argv: list[str]) -> list[str]:
    """``robot=path/to/hand.yaml`` (a robot config outside ``configs/robot/``, INTERFACE.md) as
    the overrides Hydra understands: the ``robot`` group removed and ``robot: {name, config}``
    added, ``config`` the file's absolute path (the job loads it; ``name`` names the run folder).
    Every other argument is kept as it is."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if not sep or key.lstrip("+") != "robot" or not _is_robot_path(value) or "," in value:
            out.append(arg)
            continue
        path = os.path.abspath(os.path.expanduser(value))
        name = os.path.splitext(os.path.basename(path))[0] or "robot"
        try:
            import yaml

            with open(path, encoding="utf-8") as fh:
                data = yaml.safe_load(fh.read(1 << 20))
            if isinstance(data, dict) and isinstance(data.get("name"), str) and data["name"].isidentifier():
                name = data["name"]
        except (OSError, ValueError, yaml.YAMLError):
            pass  # the job's own check names the problem
        quoted = path.replace("\\", "\\\\").replace("'", "\\'")
        out += ["~robot", f"+robot.name={name}", f"+robot.config='{quoted}'"]
    return out


def _switch_groups(schema: type) -> set[str]:
    """Top-level settings groups of ``schema`` with an ``enabled`` switch (``reach``)."""
    out = set()
    for f in dataclasses.fields(schema):
        found = lookup(schema, f.name)
        if found is not None and dataclasses.is_dataclass(found[0]) and lookup(found[0], "enabled") is not None:
            out.add(f.name)
    return out


def switch_overrides(argv: list[str], schema: type) -> list[str]:
    """A switched group's overrides as Hydra takes them: the config holds ``reach: {enabled: false}``
    and the rest of the group's defaults live in its dataclass, so ``reach=true`` becomes
    ``reach.enabled=true`` and ``reach.KEY=V`` (or ``+reach.KEY=V``) becomes ``++reach.KEY=V``: both
    orders of ``reach=true reach.timeout_s=10`` give the group switched on with that setting."""
    if not dataclasses.is_dataclass(schema):
        return list(argv)
    groups = _switch_groups(schema)
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        bare = key.lstrip("+")
        group, dot, _ = bare.partition(".")
        if not sep or group not in groups or key.startswith("~"):
            out.append(arg)
        elif not dot:
            out.append(f"{group}.enabled={value}")
        else:
            out.append(f"++{bare}={value}")
    return out


def hydra_overrides(argv: list[str], schema: type) -> list[str]:
    """A user's command line as Hydra takes it: a robot config by path
    (:func:`robot_path_overrides`) and a switched group (:func:`switch_overrides`) rewritten."""
    return switch_overrides(robot_path_overrides(list(argv)), schema)


def run_cli(main: Callable[[], None], schema: type, argv: list[str] | None = None, config_name: str | None = None,
            prepare: Callable[[dict, str], Any] | None = None) -> None:
    """Check the command line, then run the Hydra ``main``; a refusal before the job starts is one
    line on stderr, exit 2, and nothing written.

    Args:
        main: the ``@hydra.main`` function.
        schema: the job's settings dataclass (:mod:`graspnet_torch.jobs.configs`).
        config_name, prepare: the config of a single run (or of each job of a sweep) is composed
            once here and handed to ``prepare(cfg, run_dir)``, the job's own checks (problem,
            output path, memory...), so that a refusal happens before Hydra makes any folder.
    """
    import torch

    global _job_started
    _job_started = False  # a new command (a test may run several in one process)
    # the checks run on one thread (a busy machine, docs/solvers.md, "Threads"); every job sets its own count
    torch.set_num_threads(1)
    if argv is None:
        sys.argv[1:] = hydra_overrides(sys.argv[1:], schema)  # Hydra's main reads sys.argv
        argv = sys.argv[1:]
    else:
        argv = hydra_overrides(argv, schema)
    with remembering_interrupts():  # a Ctrl-C that a library turns into another error or swallows: one line
        _checks_then_main(main, schema, argv, config_name, prepare)


def _checks_then_main(main: Callable[[], None], schema: type, argv: list[str], config_name: str | None,
                      prepare: Callable[[dict, str], Any] | None) -> None:
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    try:
        if os.environ.get("GRASPNET_TORCH_NO_PRECHECK") == "1":  # benchmarks/bench_validation.py only
            raise _SkipChecks
        check_overrides(argv, schema)
        if prepare is not None and config_name is not None:
            for cfg, run_dir in compose_for_check(config_name, argv):
                prepare(cfg, run_dir)
    except _SkipChecks:
        pass
    except KeyboardInterrupt:  # Ctrl-C while the settings are checked: nothing started, nothing written
        exit_interrupted(False)
    except Exception as exc:
        if interrupted():  # a Ctrl-C that a library turned into another exception
            exit_interrupted(False)
        if not isinstance(exc, (GraspnetError, HydraException, OmegaConfBaseException)):
            raise
        say(f"error: {_one_line(exc)}")
        sys.exit(2)
    if interrupted():  # a Ctrl-C that a library swallowed during the checks (pytorch_kinematics' optional
        exit_interrupted(False)  # import of mujoco catches the ImportError a Ctrl-C can become): nothing written
    os.environ["HYDRA_FULL_ERROR"] = "1"  # let exceptions reach us instead of Hydra's multi-line report
    sweep = bool({"-m", "--multirun"} & set(argv))  # its jobs may run in other processes, started or not
    try:
        main()
    except KeyboardInterrupt:  # Ctrl-C while Hydra composes the run (a slow start), runs a sweep, or closes it
        exit_interrupted(_job_started or sweep)
    except Exception as exc:
        if interrupted():  # a Ctrl-C that Hydra's or omegaconf's clean-up turned into another exception
            exit_interrupted(_job_started or sweep)
        if _job_started:
            raise
        if isinstance(exc, (HydraException, OmegaConfBaseException)):
            say(f"error: {_one_line(exc)}")
            sys.exit(2)
        if isinstance(exc, OSError):  # e.g. a run folder Hydra cannot make
            what = f"{clip(str(exc.filename), 200)}: " if exc.filename else ""
            say(f"error: {what}{exc.strerror or _one_line(exc)}")
            sys.exit(2)
        raise


class _SkipChecks(Exception):
    pass
