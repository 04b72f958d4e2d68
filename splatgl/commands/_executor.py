"""The options every command that runs tasks shares (``--workers``, ``--executor``,
``--ray-address``, ``--ray-gpus``) and the :class:`~splatgl.tasks.executor.Executor` they name."""

from __future__ import annotations

import argparse

from ..errors import SplatglError
from ..tasks.executor import Executor, ExecutorKind


def add_executor_arguments(p: argparse.ArgumentParser, what: str, ray_chunk: str) -> argparse._ArgumentGroup:
    """``--workers``, ``--executor``, ``--ray-address``, ``--ray-gpus`` (one wording for every
    command; ``what`` says what is split, ``ray_chunk`` what one Ray task does)."""
    g = p.add_argument_group("running on more processes or machines")
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help=f"run in N local processes, each with its own context and copy of the "
                        f"scene, on {what} (default 1: this process)")
    g.add_argument("--executor", choices=[k.value for k in ExecutorKind], default="local",
                   help=f"'local' (this process, or --workers processes) or 'ray' ({ray_chunk}, on "
                        "a local Ray or the cluster at --ray-address; install with "
                        "pip install 'splatgl[ray]')")
    g.add_argument("--ray-address", default=None, metavar="ADDRESS",
                   help="with --executor ray: the cluster to join ('auto' for the one this node "
                        "belongs to; default: start a local Ray)")
    g.add_argument("--ray-gpus", type=float, default=0.0, metavar="N",
                   help="with --executor ray: GPUs each task reserves (default 0, so CPU-only "
                        "clusters work)")
    return g


def executor_from_args(args: argparse.Namespace) -> Executor:
    """The :class:`Executor` the options name; checks them (and that Ray is importable)."""
    if args.workers < 1:
        raise SplatglError(f"--workers must be at least 1, got {args.workers}")
    kind = ExecutorKind(args.executor)
    if kind is ExecutorKind.RAY and args.workers != 1:
        raise SplatglError("--workers is for --executor local; Ray decides where its tasks run")
    if not args.ray_gpus >= 0:
        raise SplatglError(f"--ray-gpus must be 0 or more, got {args.ray_gpus}")
    if kind is not ExecutorKind.RAY and (args.ray_address is not None or args.ray_gpus):
        raise SplatglError("--ray-address and --ray-gpus need --executor ray")
    if kind is ExecutorKind.RAY:
        from ..tasks.ray import import_ray

        import_ray()  # the install hint before any work
    return Executor(kind, args.workers, args.ray_address, args.ray_gpus)
