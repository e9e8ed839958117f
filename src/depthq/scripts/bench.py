"""Measure the speed targets (benchmarks, never timed tests); the last line is the figure."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.blocks.migrations import RENAMED_EVAL_SETTINGS
from depthq.errors import ConfigError
from depthq.flags import add_config_arguments, config_flags, config_from_args, flag_name


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="what", required=True, metavar="WHAT")
    sim = sub.add_parser("sim", help="env steps/s, camera + LiDAR at full resolution (target ≥ 120)")
    sim.add_argument("--steps", type=int, default=1000, help="steps per worker")
    sim.add_argument("--workers", type=int, default=1, help="processes, each stepping its own env")
    sim.add_argument("--family", default="paper", help="the canyon family driven: paper or hard")
    sim.add_argument("--look", default=None,
                     help="looks measured in turns, comma-separated, e.g. colours,textured: "
                     "names or folders of images (docs/design.md#looks; default: the family's own)")
    col = sub.add_parser(
        "collect", help="collection steps/s with storage, 1 and W workers (≥ 100 per worker)"
    )
    col.add_argument("--runs", type=int, default=20, help="runs collected (and stored) per measurement")
    col.add_argument("--workers", type=int, default=2, help="worker processes of the second measurement")
    again = sub.add_parser("rerender", help="a dataset's runs rendered again in other looks: frames/s with "
                           "storage (`dataset rerender`), beside the collector's")
    again.add_argument("--runs", type=int, default=10, help="runs collected, then rendered in each look")
    again.add_argument("--looks", default="textured,broad",
                       help="looks measured in turns, comma-separated: names or folders of images")
    again.add_argument("--workers", type=int, default=1, help="worker processes of both")
    feat = sub.add_parser("features", help="trunk features/s end to end on a dataset's frames (≥ 300)")
    feat.add_argument("--data", type=Path, required=True, help="a dataset folder")
    feat.add_argument("--frames", type=int, default=1024, help="dataset frames put through the trunk")
    feat.add_argument("--precision", default="fp32",
                      help="trunk precisions measured one after the other, comma-separated: fp32,bf16")
    tr = sub.add_parser("train", help="head training samples/s and its ratio to matmul FLOP/s (≥ 0.6)")
    tr.add_argument("--seconds", type=float, default=10.0, help="seconds of head training measured")
    tr.add_argument("--precision", default="fp32",
                    help="precisions measured side by side, comma-separated: fp32,bf16 (train --precision)")
    tr.add_argument("--threads", type=int, default=None, help="torch threads (default: this process's cores)")
    tr.add_argument("--head-form", default=None,
                    help="Depth-Q-Net head forms measured side by side, comma-separated, e.g. "
                         "depth_first,concat (train --head-form; default: the default head's)")
    tr.add_argument("--hidden", default=None,
                    help="hidden widths measured side by side, comma-separated, e.g. 1024,4096 (train "
                         "--hidden; default: the default head's)")
    tr.add_argument("--tune-stages", default=None,
                    help="trunk stages tuned, measured side by side, comma-separated, e.g. 0,1,2 (train "
                         "--tune-stages: the last N stages trained with the head on cached activations; "
                         "default: 0, the head alone)")
    pol = sub.add_parser("policy", help="ms per decision, frame in → action out (≤ 10 ms median)")
    pol.add_argument(
        "--policy", action="append", default=None,
        help="a checkpoint folder or onnx:PATH; repeat to compare (default: an untrained Depth-Q-Net)",
    )
    pol.add_argument("--decisions", type=int, default=200, help="single decisions timed per policy")
    pol.add_argument("--batches", type=int, default=None,
                     help="act_batch calls on 20 frames, as lock-step evaluation decides for 20 canyons "
                     "(default: --decisions / 20, at least 1)")
    pol.add_argument("--threads", type=int, default=None,
                     help="torch threads (default: this process's cores; an evaluation worker has 1)")
    from depthq.evaluate.online import EvalConfig  # MuJoCo: only when this verb's flags are built
    from depthq.networks import acting_classes

    # The networks' acting settings, as `depthq evaluate` takes them (--depth.switch: a lookahead
    # Depth-Q-Net's largest candidate set, docs/design.md#lookahead-selection; --switch, as before).
    acting = tuple(f.path for f in config_flags(EvalConfig) if f.path.partition(".")[0] in acting_classes())
    add_config_arguments(pol, EvalConfig, only=acting,
                         aliases={RENAMED_EVAL_SETTINGS["switch"]: (flag_name("switch"),)})
    ev = sub.add_parser("evaluate", help="one policy in 20 canyons, one canyon at a time vs lock-step")
    ev.add_argument("--policy", required=True, help="'heuristic', a checkpoint folder or onnx:PATH")
    ev.add_argument("--canyons", default="val:1000-1019",
                    help="a canyon set, as evaluate's --canyons (default: 20 val canyons)")
    ev.add_argument("--workers", type=int, default=2, help="processes, each driving its share of the canyons")
    ev.add_argument("--time-limit", type=float, default=None, help="seconds per run [the family's]")
    step = sub.add_parser(
        "step", help="where an evaluation step's time goes, and the floor it sets for lock-step evaluation"
    )
    step.add_argument("--policy", default=None,
                      help="a checkpoint folder (default: an untrained Depth-Q-Net of the default trunk)")
    step.add_argument("--canyon", default="val:1000", help="the canyon driven (its family's world)")
    step.add_argument("--steps", type=int, default=50, help="steps timed, part by part")
    step.add_argument("--threads", type=int, default=1, help="torch threads (an evaluation worker has 1)")
    dev = sub.add_parser(
        "device", help="the whole picture on one device: a preset's stage times, then features, training, "
        "a decision, a step's parts and env steps/s measured on what it made (OUT/bench.json)")
    dev.add_argument("--preset", default="quick",
                     help="the preset run (resumed) into OUT/sweep (default: quick)")
    dev.add_argument("--out", type=Path, required=True, help="output folder (created; its sweep resumed)")
    dev.add_argument("--seconds", type=float, default=10.0, help="seconds of head training measured")
    dev.add_argument("--steps", type=int, default=200, help="env steps per worker, one worker per core")
    for parser in (col, ev, step):
        parser.add_argument("--look", default=None,
                            help="the look driven in: flat, colours, textured, heldout, broad or a folder of "
                            "images (docs/design.md#looks; default: the canyons' family's own)")
    for parser in (sim, col, again, feat, tr, pol, ev, step, dev):
        parser.add_argument("--json", action="store_true", help="print the result as one JSON line")
    for parser in (feat, tr, pol, ev, step, dev):
        parser.add_argument("--device", default="auto", help=DEVICE_HELP)


def _positive(name: str, value: float) -> None:
    if not value > 0:
        raise ConfigError(f"{name} must be > 0, got {value}")


def _check_look(look: str | None) -> None:
    """A bad --look fails here, before any work."""
    if look is not None:
        from depthq.sim.look import check_look  # mujoco's package: off the CLI's startup

        check_look(look)


def _precisions(text: str) -> tuple[str, ...]:
    """--precision fp32,bf16 → ('fp32', 'bf16')."""
    return tuple(p.strip() for p in text.split(","))


def _measure(args: argparse.Namespace) -> tuple[dict, str]:
    """Run the chosen benchmark; returns its result and the one-line figure."""
    if args.what == "sim":
        _positive("--steps", args.steps)
        _positive("--workers", args.workers)
        from depthq.bench.sim import bench_sim  # mujoco: off the CLI's startup
        from depthq.sim.world import WorldConfig

        looks = (None,) if args.look is None else tuple(look.strip() for look in args.look.split(","))
        for look in looks:  # a bad family or look fails here, before any worker starts
            WorldConfig(family=args.family, **({} if look is None else {"look": look}))
        r = bench_sim(args.steps, args.workers, args.family, looks)
        each = r["looks"] if "looks" in r else {r["look"]: r}
        figure = "; ".join(f"{look}: {e['steps_per_s']} env steps/s" + (
            f" (×{r['relative'][look]})" if "relative" in r else "") for look, e in each.items())
        last = next(iter(each.values()))
        return r, f"{figure} with {last['workers']} worker(s), max RSS {last['max_rss_mb']} MB"
    if args.what == "collect":
        _positive("--runs", args.runs)
        _positive("--workers", args.workers)
        from depthq.bench.collect import bench_collect  # mujoco: off the CLI's startup

        _check_look(args.look)
        r = bench_collect(args.runs, tuple(sorted({1, args.workers})), args.look)
        last = r[f"w{args.workers}"]
        return r, (
            f"{r['w1']['steps_per_s']} steps/s with 1 worker, {last['steps_per_s']} with {args.workers} "
            f"(×{r.get('speedup', 1.0)}), {last['kb_per_frame']} KB per frame"
        )
    if args.what == "rerender":
        _positive("--runs", args.runs)
        _positive("--workers", args.workers)
        from depthq.bench.rerender import bench_rerender  # mujoco: off the CLI's startup

        looks = tuple(look.strip() for look in args.looks.split(","))
        for look in looks:
            _check_look(look)
        r = bench_rerender(args.runs, looks, args.workers)
        each = "; ".join(f"{look}: {e['frames_per_s']} frames/s ({e['ms_per_frame']} ms, "
                         f"{e['kb_per_frame']} KB per frame)" for look, e in r["looks"].items())
        c = r["collect"]
        return r, (f"re-rendered {each}; collected in {c['look']}: {c['frames_per_s']} frames/s "
                   f"({r['workers']} worker(s))")
    if args.what == "features":
        _positive("--frames", args.frames)
        from depthq.bench.features import bench_features  # torch: off the CLI's startup

        precisions = _precisions(args.precision)
        r = bench_features(args.data, n=args.frames, device=args.device, precisions=precisions)
        each = [f"{p['frames_per_s']} frames/s" + (f" ({name})" if len(precisions) > 1 else "")
                for name, p in r["precisions"].items()]
        check = r["check"]
        return r, ("; ".join(each) + f" ({r['trunk']}, {r['input_size']} px, decode + resize + trunk); "
                   f"the cache's check when read: {check['frames_per_s']:.0f} frames/s "
                   f"({check['mb_per_s']:.0f} MB/s, {100 * check['share_of_compute']:.2f} % of computing "
                   "them)")
    if args.what == "train":
        _positive("--seconds", args.seconds)
        from depthq.bench.train import bench_train  # torch: off the CLI's startup

        if args.threads is not None:
            _positive("--threads", args.threads)
        precisions = _precisions(args.precision)
        forms = (None,) if args.head_form is None else tuple(args.head_form.split(","))
        hiddens = (None,) if args.hidden is None else _widths(args.hidden)
        tunes = (0,) if args.tune_stages is None else _counts("--tune-stages", args.tune_stages)
        r = bench_train(args.seconds, device=args.device, precisions=precisions, threads=args.threads,
                        forms=forms, hiddens=hiddens, tunes=tunes)
        each = [(f"{p['samples_per_s']} samples/s (the last {p['tune_stages']} trunk stages and the head)"
                 if p["tune_stages"] else
                 f"{p['samples_per_s']} head samples/s, {p['head_gflops']} GFLOP/s = {p['ratio']} × matmul's")
                + (f" ({name})" if len(r["variants"]) > 1 else "") for name, p in r["variants"].items()]
        return r, "; ".join(each) + f" {r['matmul_gflops']} fp32 GFLOP/s ({r['threads']} threads)"
    if args.what == "evaluate":
        _positive("--workers", args.workers)
        from depthq.bench.evaluate import bench_evaluate  # torch, mujoco: off the CLI's startup
        from depthq.evaluate.online import parse_canyon_set
        from depthq.policies.spec import PolicySpec

        canyons = parse_canyon_set(args.canyons)
        _check_look(args.look)
        spec = PolicySpec.parse(args.policy)
        r = bench_evaluate(spec, canyons, args.workers, args.time_limit, args.device, args.look)
        return r, (
            f"{r['policy']} in {r['canyons']} canyons ({r['decisions']} decisions), {r['workers']} "
            f"worker(s): {r['sequential_s']} s one canyon at a time, {r['lockstep_s']} s in lock-step "
            f"(×{r['speedup']}), {'the same' if r['same_runs'] else 'DIFFERENT'} runs"
        )
    if args.what == "device":
        _positive("--seconds", args.seconds)
        _positive("--steps", args.steps)
        from depthq.bench.device import bench_device  # torch, mujoco: off the CLI's startup
        from depthq.pipeline.presets import get_preset

        get_preset(args.preset)  # an unknown preset fails here, before any work
        r = bench_device(args.out, args.preset, args.device, args.seconds, args.steps)
        parts = {"stages": f"{r['stage_total_s']} s of stage time",
                 "features": f"{r['features']['precisions']['fp32']['frames_per_s']} frames/s",
                 "train": f"{r['train']['variants'][next(iter(r['train']['variants']))]['ratio']} × matmul",
                 "decision": f"{r['policy']['policies'][0]['ms_median']} ms",
                 "step floor": f"{r['step']['floor_ms_per_step']} ms",
                 "sim": f"{r['sim']['steps_per_s']} env steps/s on {r['sim']['workers']} workers"}
        return r, f"{args.preset} on {r['device']}: " + "; ".join(f"{k} {v}" for k, v in parts.items())
    if args.what == "step":
        _positive("--steps", args.steps)
        _positive("--threads", args.threads)
        from depthq.bench.step import bench_step  # torch, mujoco: off the CLI's startup

        _check_look(args.look)
        r = bench_step(args.policy, args.canyon, args.steps, args.device, args.threads, args.look)
        parts = ", ".join(f"{k} {v}" for k, v in {**r["sim_ms"], **r["policy_ms"]}.items())
        return r, (
            f"ms: {parts}; floor {r['floor_ms_per_step']} ms per lock-step step; a batch of {r['batch']} "
            f"decisions costs at least {r['batch_bound']} × one ({r['threads']} threads)"
        )
    _positive("--decisions", args.decisions)
    if args.batches is not None and args.batches < 0:
        raise ConfigError(f"--batches must be >= 0, got {args.batches}")
    if args.threads is not None:
        _positive("--threads", args.threads)
    from depthq.bench.policy import bench_policy  # torch, mujoco: off the CLI's startup
    from depthq.policies.spec import PolicySpec

    specs = [PolicySpec.parse(spec) for spec in args.policy] if args.policy else None
    from depthq.evaluate.online import EvalConfig

    acting = config_from_args(EvalConfig, args).acting
    r = bench_policy(specs, args.decisions, args.device, args.batches, args.threads, acting)
    each = [f"{p['policy']} ({p['candidates']} candidates): {p['ms_median']} ms median ({p['ms_p90']} ms p90)"
            + _in_batch(p, r["batch"]) for p in r["policies"]]
    return r, "per decision: " + "; ".join(each) + f" ({r['threads']} threads)"


def _in_batch(policy: dict, size: int) -> str:
    """A policy's batch figure, if it has one."""
    if "batch_ms_median" not in policy:
        return ""
    per_batch = policy["batch_ms_median"]
    return f", {policy['batch_ms_per_decision']} ms in a batch of {size} ({per_batch} ms per batch)"


def run(args: argparse.Namespace) -> int:
    result, figure = _measure(args)
    print(json.dumps(result) if args.json else figure)
    return 0


def _counts(flag: str, text: str) -> tuple[int, ...]:
    """'0,1,2' → (0, 1, 2); each is checked where it is used (`train --tune-stages` checks its range)."""
    try:
        return tuple(int(part) for part in text.split(","))
    except ValueError:
        raise ConfigError(f"{flag} takes integers such as 0,1,2; got {text!r}") from None


def _widths(text: str) -> tuple[int, ...]:
    """'1024,4096' → (1024, 4096); each is checked as `train --hidden` checks it."""
    try:
        return tuple(int(part) for part in text.split(","))
    except ValueError:
        raise ConfigError(f"--hidden takes widths such as 1024,4096; got {text!r}") from None
