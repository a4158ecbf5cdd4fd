"""``tbha-run PIPELINE``: check a pipeline, run what its outputs need, write the run directory."""
from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

from .common import EXIT_FAILED, EXIT_OK, add_run_arguments, guarded, parse_assignments


def run_command(args: argparse.Namespace) -> int:
    from ..core.cache import Cache
    from ..core.errors import NodeFailed
    from ..core.progress import Reporter
    from ..core.registry import default_registry, load_plugin_modules
    from ..core.runner import effective_jobs, load_graph, run_graph

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
    jobs = effective_jobs(graph, args.jobs)
    print(f"tbha-run {args.pipeline}: {len(graph.nodes)} nodes, executor {executor}"
          f"{f' ({jobs} jobs)' if executor == 'local' and jobs > 1 else ''}, cache {'off' if cache is None else cache.root}", file=sys.stderr)
    try:
        run = run_graph(graph, out_dir=out_dir, outputs=args.output, cache=cache, executor=executor,
                        scheduler=args.scheduler, reporter=reporter, workers=args.workers, jobs=args.jobs)
    except NodeFailed as e:
        print(f"error: {e.format()}", file=sys.stderr)
        print(f"the run failed; no run directory was written to {out_dir}. Nodes that finished are cached: "
              f"fix the problem and run the same command again to resume.", file=sys.stderr)
        return EXIT_FAILED
    print_summary(run, out_dir, verbose=getattr(args, "verbose", False))
    return EXIT_OK


#: the figures the short summary shows when the metrics have them (every one: --verbose; docs/metrics.md)
HEADLINE = ("tracked_pct", "reprojection_px_median", "fit_px_median", "mpjpe_mm", "pa_mpjpe_mm", "export_mpjpe_mm", "export_pa_mpjpe_mm",
            "focal_px", "camera_height_m", "camera_distance_m", "camera_tilt_deg")


def focal_origin(source: str) -> str | None:
    """The summary's short tag for ``metrics.json``'s ``focal_source``: where the focal length came from (``None``:
    the take alone, whose span the summary shows instead)."""
    return {"given": "given", "room": "room lines", "lens": "lens file"}.get(source.split(" ")[0])


def print_summary(run, out_dir: Path, verbose: bool = False) -> None:
    """At most 15 lines (more with ``verbose``): what ran, the verdict and its reasons, the headline
    figures of a ``metrics.json`` output, the warnings, where the outputs are."""
    from ..core.progress import fmt_value

    ran = sum(r.status == "ran" for r in run.results.values())
    cached = sum(r.status == "cached" for r in run.results.values())
    print(f"\ndone in {run.seconds:.2f} s: {ran} node(s) ran, {cached} from cache")
    metrics = None
    if "metrics.json" in run.graph.outputs and run.graph.outputs["metrics.json"][0] in run.results:
        metrics = run.output("metrics.json")
    warnings = [f"{w['node']}: {w['message']}" for w in run.node_warnings()]
    if isinstance(metrics, dict):
        warnings = [str(w) for w in metrics.get("warnings") or []] or warnings
        frames = metrics.get("frames")
        fps = f", {frames / run.seconds:.1f} fps achieved" if isinstance(frames, (int, float)) and run.seconds > 0 and ran and not cached else ""
        if "verdict" in metrics:
            reasons = [str(r) for r in metrics.get("verdict_reasons") or [] if not str(r).startswith("warning: ")]
            print(f"  verdict: {metrics['verdict']}" + (f" ({'; '.join(reasons)[:200]})" if reasons else ""))
        if verbose:
            if fps:
                print(f"  {'fps achieved':<28} {frames / run.seconds:.1f}")
            for k, v in metrics.items():
                if not isinstance(v, (dict, list)):
                    print(f"  {k:<28} {fmt_value(v)}")
        else:
            if frames is not None:
                print(f"  {frames} frames{fps}")
            shown = [k for k in HEADLINE if isinstance(metrics.get(k), (int, float)) and not isinstance(metrics.get(k), bool)]
            text = {k: fmt_value(metrics[k]) for k in shown}
            lo, hi = metrics.get("focal_fits_px_min"), metrics.get("focal_fits_px_max")
            source = str(metrics.get("focal_source", ""))
            if "focal_px" in text and isinstance(lo, (int, float)) and isinstance(hi, (int, float)) and hi > lo:
                text["focal_px"] += f" (fits {lo:.0f}-{hi:.0f})"  # how open the take leaves it
            elif "focal_px" in text and source:  # where it came from: given, a lens file, or the room's lines
                origin = focal_origin(source)
                text["focal_px"] += f" ({origin})" if origin else ""
            for i in range(0, len(shown), 3):  # three a line: the summary stays short with warnings below
                print("  " + "   ".join(f"{k} {text[k]}" for k in shown[i : i + 3]))
    if warnings:
        print(f"  {len(warnings)} warning(s):")
        for w in warnings if verbose else warnings[:3]:
            print(textwrap.fill(w, width=110, initial_indent="    - ", subsequent_indent="      "))  # whole, wrapped
        if not verbose and len(warnings) > 3:
            print(f"    ... and {len(warnings) - 3} more (--verbose, or metrics.json / manifest.json)")
    written = [name for name, (nid, _) in run.graph.outputs.items() if nid in run.results]
    if verbose:
        print(f"outputs in {out_dir}/:")
        for name in written + ["manifest.json"]:
            print(f"  {out_dir / name}")
    else:
        print(textwrap.shorten(f"outputs in {out_dir}/: {', '.join(written + ['manifest.json'])}", width=200, placeholder=" ..."))
        if isinstance(metrics, dict):
            print("every figure: --verbose or metrics.json (explained in docs/metrics.md)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="tbha-run", description="Run a tbha-graph pipeline and write its outputs to a run directory.")
    add_run_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return guarded(lambda: run_command(args))


if __name__ == "__main__":
    sys.exit(main())
