"""``tbha-run PIPELINE``: check a pipeline, run what its outputs need, write the run directory."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..core.cache import Cache
from ..core.errors import NodeFailed
from ..core.progress import Reporter, fmt_value
from ..core.registry import default_registry, load_plugin_modules
from ..core.runner import load_graph, run_graph
from .common import EXIT_FAILED, EXIT_OK, add_run_arguments, guarded, parse_assignments


def run_command(args: argparse.Namespace) -> int:
    reporter = Reporter(quiet=args.quiet)
    reg = default_registry()
    if args.plugin:
        load_plugin_modules(args.plugin, reg)
    for f in reg.failures:
        reporter.warn(str(f))
    graph = load_graph(args.pipeline, sets=parse_assignments(args.set, "--set"), vars=parse_assignments(args.var, "--var"), registry=reg)
    out_dir = Path(args.out) if args.out else Path("runs") / Path(args.pipeline).stem
    cache = None if args.no_cache else Cache(args.cache_dir) if args.cache_dir else Cache()
    executor = "dask" if args.scheduler else args.executor
    print(f"tbha-run {args.pipeline}: {len(graph.nodes)} nodes, executor {executor}, cache {'off' if cache is None else cache.root}", file=sys.stderr)
    try:
        run = run_graph(graph, out_dir=out_dir, outputs=args.output, cache=cache, executor=executor,
                        scheduler=args.scheduler, reporter=reporter, workers=args.workers)
    except NodeFailed as e:
        print(f"error: {e.format()}", file=sys.stderr)
        print(f"the run failed; no run directory was written to {out_dir}. Nodes that finished are cached: "
              f"fix the problem and run the same command again to resume.", file=sys.stderr)
        return EXIT_FAILED
    print_summary(run, out_dir)
    return EXIT_OK


def print_summary(run, out_dir: Path) -> None:
    """One screen: what ran, the figures of a ``metrics.json`` output if there is one, where outputs are."""
    ran = sum(r.status == "ran" for r in run.results.values())
    cached = sum(r.status == "cached" for r in run.results.values())
    print(f"\ndone in {run.seconds:.2f} s: {ran} node(s) ran, {cached} from cache")
    if "metrics.json" in run.graph.outputs and run.graph.outputs["metrics.json"][0] in run.results:
        metrics = run.output("metrics.json")
        if isinstance(metrics, dict):
            frames = metrics.get("frames")
            if isinstance(frames, (int, float)) and run.seconds > 0 and ran:
                print(f"  {'fps achieved':<28} {frames / run.seconds:.1f}")
            for k, v in metrics.items():
                if not isinstance(v, (dict, list)):
                    print(f"  {k:<28} {fmt_value(v)}")
    print(f"outputs in {out_dir}/:")
    written = [name for name, (nid, _) in run.graph.outputs.items() if nid in run.results]
    for name in written + ["manifest.json"]:
        print(f"  {out_dir / name}")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="tbha-run", description="Run a tbha-graph pipeline and write its outputs to a run directory.")
    add_run_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return guarded(lambda: run_command(args))


if __name__ == "__main__":
    sys.exit(main())
