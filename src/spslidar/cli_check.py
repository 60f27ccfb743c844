"""``spslidar check``: the conformance checks of :mod:`spslidar.testing` over registered
stages, for a researcher's own (``spslidar --plugin mystages check --plugins-only``) as for
the built-in ones; the sub-command's parser and its command, as :mod:`spslidar.cli`
registers them."""

from __future__ import annotations

import argparse

__all__ = ["add_check_parser", "cmd_check"]

#: exit status where a stage breaks its contract (bad input stays 2)
EXIT_FAILED = 1


def add_check_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``check`` sub-command to ``add_subparsers()``.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``spslidar`` parser.

    Returns
    -------
    argparse.ArgumentParser
        The new sub-parser; :func:`cmd_check` runs it.
    """
    from .testing import STAGE_KINDS

    p = subparsers.add_parser(
        "check", help="check registered stages (yours: --plugin) against their contracts",
        description="Run the conformance checks of spslidar.testing, which the project's own "
                    "tests run over every built-in stage, on registered stages: a code "
                    "family's bits and correlation, a pattern operator's adjoint, a detector "
                    "model's mean, a solver's optimum against a reference, a regulariser's "
                    "prox, a depth estimator's noiseless recovery, a scene kind's shape. One "
                    "line per stage; exit status 1 if any breaks its contract.")
    p.add_argument("stages", nargs="*", metavar="KIND[:NAME]",
                   help=f"stage kinds ({', '.join(STAGE_KINDS)}) or single stages "
                        f"(depth:mrf); default every kind")
    p.add_argument("--plugins-only", action="store_true",
                   help="only the stages a plugin registered (--plugin or SPSLIDAR_PLUGINS)")
    return p


def _selection(specs: list[str]) -> list[tuple[str, str | None]]:
    """``KIND[:NAME]`` arguments as ``(kind, name or None)``, in any case as the registries
    read names (``DEPTH:MRF``), each stage once (``depth:mrf depth:mrf``, or ``depth
    depth:mrf``, checked it twice and counted it twice: an outside audit of 2026-12-03);
    unknown ones are ConfigErrors."""
    from .errors import ConfigError
    from .testing import STAGE_KINDS, registry_of

    out: list[tuple[str, str | None]] = []
    for spec in specs:
        kind, _, name = spec.partition(":")
        kind = kind.lower() if kind.lower() in STAGE_KINDS else kind
        if kind not in STAGE_KINDS:
            raise ConfigError(f"unknown stage kind {kind!r} in {spec!r}; choose one of "
                              f"{', '.join(STAGE_KINDS)}")
        name = registry_of(kind).canonical(name) if name else name
        if name and name not in registry_of(kind):
            raise ConfigError(f"unknown {registry_of(kind).kind} {name!r}; choose one of "
                              f"{', '.join(registry_of(kind).names())}")
        out.append((kind, name or None))
    whole = {k for k, n in out if n is None}
    return list(dict.fromkeys((k, n) for k, n in out if n is None or k not in whole))


def cmd_check(args: argparse.Namespace) -> int:
    """Run ``spslidar check``; return the exit status (0: every stage passes, 1: one breaks
    its contract, 2: an unknown kind or name, or nothing to check)."""
    from .errors import ConfigError
    from .testing import STAGE_KINDS, check_stages, registry_of

    chosen = _selection(args.stages) or [(kind, None) for kind in STAGE_KINDS]

    def say(r) -> None:
        # (a plugin's stage under a built-in's name was checked as "ok depth argmax", the
        # replacement unsaid, where run warns of it: an outside audit of a plugin developer)
        reg = registry_of(r.kind)
        old = reg.replaced(r.name)
        # (as run says it: where the implementation differs, not a re-registration of the
        # built-in's own with other defaults, a review)
        mine = (f"a plugin's, replacing the built-in {old.target}"
                if old is not None and r.name in reg and reg.get(r.name).target != old.target
                else "")
        if r.ok:
            # (a contract that could not run is said, not counted passed, an audit of plugins)
            skipped = "".join(f"; skipped: {c}" for c in r.skipped)
            print(f"ok    {r.kind} {r.name} ({len(r.passed)} contracts, {r.seconds:.1f} s"
                  f"{skipped}{', ' + mine if mine else ''})", flush=True)
        else:
            print(f"FAIL  {r.kind} {r.name}{f' ({mine})' if mine else ''}: {r.error}",
                  flush=True)

    results = []
    for kind, name in chosen:
        results += check_stages([kind], None if name is None else [name],
                                plugins_only=args.plugins_only, on_result=say)
    if not results:
        named = [f"{k}:{n}" for k, n in chosen if n is not None]
        raise ConfigError("no stage to check" + (
            f": {', '.join(named)} {'is' if len(named) == 1 else 'are'} built in, and "
            f"--plugins-only checks only a plugin's stages" if named and args.plugins_only
            else ": no plugin registered one of those kinds" if args.plugins_only else ""))
    failed = [r for r in results if not r.ok]
    # (on stdout either way, after the lines it counts: it went to stderr on a failure, so a
    # script reading stdout lost the count exactly then, an audit)
    print(f"{len(results) - len(failed)} of {len(results)} stages pass their contracts "
          f"(each built with its options at their defaults)")
    return EXIT_FAILED if failed else 0
