"""The reproduction's outputs: ``results.json`` (every number), the figures, and
``report.md`` (each table with the paper's figure beside the simulation's, and the
difference)."""

from __future__ import annotations

import os
import platform
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.baselines.curves import CurvePoint, plot_curves
from dvrk_gym.calibration.benchmark import YAW_SETTINGS
from dvrk_gym.calibration.search import SearchResult, plot_search
from dvrk_gym.evaluation.trials import unpicked_note
from dvrk_gym.parallel.task_graph import locate_in_folder
from dvrk_gym.utils.source_fingerprint import SHORT_DIGEST_CHARS, source_fingerprint

PAPER_PHASE1 = {"raw": paper.PHASE1_RAW_SAMPLES, "kept": paper.PHASE1_KEPT_SAMPLES}
"""The paper's Phase I: raw samples and those both cameras saw at the same place."""
_PACKAGES = ("dvrk-gym", "pybullet", "gymnasium", "numpy", "torch", "scikit-learn", "stable-baselines3")


def _versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    versions["dvrk_gym source sha256"] = source_fingerprint().sha256[:SHORT_DIGEST_CHARS]  # the run folder's stamp holds it whole
    return versions


def _per_setting(values: tuple[float, ...]) -> dict[str, float]:
    """The paper's figures of a method by setting label."""
    return dict(zip((label for label, _ in YAW_SETTINGS), values))


def relative_to_run(path: str, run_folder: Path) -> str:
    """A path inside the run folder, relative to it (so the folder can be moved).

    A task's cached result records where the folder was when the task ran: in a folder moved
    or copied since, the file is found by the longest tail of that path that lies in
    ``run_folder``.
    """
    return os.path.relpath(locate_in_folder(path, run_folder), os.path.abspath(run_folder))


def collect_results(config: Any, task_results: dict[str, dict[str, Any]], executor: str) -> dict[str, Any]:
    """Everything the report shows, as plain numbers, from the tasks' summaries (``executor``:
    where the tasks ran, for people)."""
    calibration = task_results["calibration"]
    phase1 = calibration["phase1"]
    profile = config.profile
    moves_phase1 = profile.n_trajectories * profile.steps_per_trajectory
    methods = {}
    for method, rows in calibration["summary"].items():
        methods[method] = {
            "mean_mm": rows["all settings"]["mm"]["mean"],
            "mean_px": rows["all settings"]["pixel"]["mean"],
            "per_setting_px": {label: rows[label]["pixel"]["mean"] for label, _ in YAW_SETTINGS},
            "per_setting_mm": {label: rows[label]["mm"]["mean"] for label, _ in YAW_SETTINGS},
            "paper_mean_mm": paper.CALIBRATION_MEAN_MM.get(method),
            "paper_per_setting_px": _per_setting(paper.CALIBRATION_PIXELS[method]) if method in paper.CALIBRATION_PIXELS else None,
            "robot_moves": moves_phase1 + (calibration["phase2_touches"] if method == "DNN+RF" else 0),
        }
    search = [
        {key: task_results[name][key] for key in ("name", "family", "mean_mm2", "std_mm2", "fold_mm2", "split_folds", "epochs", "seconds")}
        for name in task_results
        if name.startswith("search_")
    ]
    debridement = []
    for name, cell in task_results.items():
        if name.startswith("debridement_"):
            reference = paper.DEBRIDEMENT_RESULTS.get((cell["calibrator"], cell["fragment"]))
            debridement.append(
                {key: value for key, value in cell.items() if key != "cached"}
                | {"paper": reference, "figure": relative_to_run(cell["figure"], config.out)}
            )
    agents = [
        {k: v for k, v in result.items() if k != "cached"} | {"model": relative_to_run(result["model"], config.out)}
        for name, result in task_results.items()
        if name.startswith("rl_")
    ]
    return {
        "settings": {**config.settings(), "workers": config.workers, "executor": executor, "versions": _versions()},
        "bias": {k: v for k, v in task_results["bias_field"].items() if k != "cached"}
        | {"figure": relative_to_run(task_results["bias_field"]["figure"], config.out)},
        "phase1": {**phase1, "kept_fraction": phase1["kept"] / max(phase1["raw"], 1), "paper": PAPER_PHASE1},
        "search": search,
        "search_paper_mm2": paper.SEARCH_MM2,
        "calibration": methods,
        "debridement": debridement,
        "debridement_paper_phase_s": paper.DEBRIDEMENT_PHASE_S,
        "paper_time_per_fragment_s": paper.TIME_PER_FRAGMENT_S,
        "rl": agents,
        "task_wall_s": {name: result["wall_s"] for name, result in task_results.items()},
        "task_cached": sorted(name for name, result in task_results.items() if result.get("cached")),
    }


def write_figures(folder: Path, data: dict[str, Any]) -> dict[str, str]:
    """Draw the figures made from several tasks' results; returns every figure's path,
    relative to the run folder."""
    folder = Path(folder)
    figures = {"bias_field": "figures/bias_field.png", "calibration_error_maps": "figures/calibration_error_maps.png"}
    if data["search"]:
        results = [SearchResult(**{**row, "fold_mm2": tuple(row["fold_mm2"])}) for row in data["search"]]
        plot_search(results, str(folder / "model_search.png"))
        figures["model_search"] = "figures/model_search.png"
    if data["rl"]:
        curves = {agent["label"]: [CurvePoint.from_json(point) for point in agent["curve"]] for agent in data["rl"]}
        table_mm = {agent["label"]: agent["mean_mm"] for agent in data["rl"]}
        title = "RL agents on GridTouch-v0: touch error against robot moves"
        plot_curves(curves, folder / "learning_curves.png", title=title, table_mm=table_mm)
        figures["learning_curves"] = "figures/learning_curves.png"
    for cell in data["debridement"]:
        figures[Path(cell["figure"]).stem] = cell["figure"]
    return figures


def _percent(sim: float, reference: float | None) -> str:
    if reference is None or not np.isfinite(sim):
        return "-"
    return f"{100.0 * (sim - reference) / reference:+.0f}%"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def _image(data: dict[str, Any], key: str, caption: str) -> list[str]:
    path = data["figures"].get(key)
    return [f"![{caption}]({path})", ""] if path else []


def render_report(data: dict[str, Any]) -> str:
    """``report.md``'s text: settings, then every table, the paper beside the simulation."""
    settings, profile = data["settings"], data["settings"]["profile"]
    lines = [
        "# dvrk-gym reproduction of Seita et al., ICRA 2018",
        "",
        f"Profile **{profile['name']}**, seed {settings['seed']}, cable bias `{settings['bias']}` "
        f"(instrument {settings['bias_seed']}), endoscope {profile['camera_resolution'][0]} x {profile['camera_resolution'][1]}, "
        f"tasks run on {_executors(data)}. " + _timing_sentence(data),
        "",
        "Every figure from the simulation, with the paper's beside it and the difference. "
        "`results.json` holds the same numbers and more (per-setting statistics, learning curves, trial rows).",
        "",
    ]
    lines += _bias_section(data) + _phase1_section(data) + _search_section(data) + _calibration_section(data)
    lines += _debridement_section(data) + _rl_section(data)
    lines += ["## Run", "", "Wall time per task (seconds; cached tasks show the time they took when they ran):", ""]
    lines += _table(
        ["task", "wall s", "cached"],
        [[name, f"{s:.1f}", "yes" if name in data["task_cached"] else ""] for name, s in data["task_wall_s"].items()],
    )
    lines += ["", "Versions: " + ", ".join(f"{k} {v}" for k, v in settings["versions"].items()), ""]
    return "\n".join(lines)


def _timing_sentence(data: dict[str, Any]) -> str:
    calls = [call for call in data["calls"] if call["tasks_run"] or call.get("interrupted")]
    runs = "; ".join(
        f"{call['wall_s'] / 60:.1f} min for {call['tasks_run']} tasks on {_where(call)}{', interrupted' if call.get('interrupted') else ''}"
        for call in calls
    )
    return f"Wall time: {runs or 'every task was cached'} (the tasks' own times add up to {data['wall_s']['tasks_total'] / 60:.1f} min)."


def _executors(data: dict[str, Any]) -> str:
    """Where the calls that ran tasks ran them (this call's executor when every task was cached
    before it: a call that only loaded results ran none)."""
    ran = list(dict.fromkeys(_where(call) for call in data["calls"] if call["tasks_run"]))
    return " and ".join(ran) if ran else data["settings"]["executor"]


def _where(call: dict[str, Any]) -> str:
    """Where a call's tasks ran (calls logged before executors were recorded name their workers)."""
    return call.get("executor") or f"{call['workers']} worker(s)"


def _bias_section(data: dict[str, Any]) -> list[str]:
    bias = data["bias"]
    yaws = ["-90", "-45", "0", "45", "90"]
    lines = [
        "## The simulated instrument",
        "",
        f"The cable model misses by {bias['raw_mean_mm']:.2f} mm on average (raw, over {bias['samples']} random moves). "
        f"A rigid fit per yaw to the cables' own error leaves {bias['rigid_mean_mm']:.2f} mm, "
        f"a smooth model {bias['smooth_mean_mm']:.2f} mm: the cables alone, before the endoscope's and the tape's errors, "
        f"which the calibrators meet too (the paper's rigid body missed by {paper.CALIBRATION_MEAN_MM['RBT']:.2f} mm, "
        f"its DNN+RF by {paper.CALIBRATION_MEAN_MM['DNN+RF']:.2f} mm; the calibration table below). "
        "Hysteresis: approaching a command "
        f"from either side changes the tip by {bias['hysteresis_gap_mm']:.2f} mm on average.",
        "",
    ]
    lines += _table(
        ["yaw (deg)"] + yaws,
        [
            ["rigid residual, random moves (mm)"] + [f"{v:.2f}" for v in bias["rigid_by_yaw_mm"]],
            ["rigid residual, 35-point grid (mm)"] + [f"{v:.2f}" for v in bias["grid_rigid_by_yaw_mm"]],
        ],
    )
    return lines + [""] + _image(data, "bias_field", "tip error after a rigid fit, per yaw")


def _phase1_section(data: dict[str, Any]) -> list[str]:
    p = data["phase1"]
    reference = p["paper"]
    rows = [
        ["raw samples", f"{p['raw']:,}", f"{reference['raw']:,}", _percent(p["raw"], reference["raw"])],
        ["kept (both cameras agree)", f"{p['kept']:,}", f"{reference['kept']:,}", _percent(p["kept"], reference["kept"])],
        ["kept fraction", f"{100 * p['kept_fraction']:.0f}%", f"{100 * reference['kept'] / reference['raw']:.0f}%", ""],
    ]
    return ["## Phase I data", ""] + _table(["", "simulation", "paper", "difference"], rows) + [""]


def _search_section(data: dict[str, Any]) -> list[str]:
    if not data["search"]:
        return []
    references = data["search_paper_mm2"]
    rows = []
    for r in sorted(data["search"], key=lambda r: r["mean_mm2"]):
        reference = references.get(r["name"])
        rows.append(
            [
                r["name"],
                f"{r['mean_mm2']:.2f} +- {r['std_mm2']:.2f}",
                f"{len(r['fold_mm2'])}/{r['split_folds']}",
                "-" if r["epochs"] is None else str(r["epochs"]),
                f"{reference:.2f}" if reference else "",
                _percent(r["mean_mm2"], reference),
            ]
        )
    authors = ", ".join(f"{name} {mm2:.2f}" for name, mm2 in paper.AUTHORS_CV_MM2.items())
    lines = [
        "## Model search (Phase I)",
        "",
        "Cross-validated mean squared L2 error of each model on this run's cleaned Phase I data, best first. "
        f"The paper's figures are on its real data (the authors' own re-run of it: {authors} mm^2).",
        "",
    ]
    short = sorted({r["epochs"] for r in data["search"] if r["epochs"] is not None and r["epochs"] < paper.DNN_EPOCHS})
    if short:  # a quick profile: the nets' gap to the paper is their training's, not the data's
        lines[-1:-1] = [
            f"The nets here trained {', '.join(map(str, short))} epochs, not the paper's {paper.DNN_EPOCHS}: their difference "
            "from the paper's figure is mostly the short training (sigmoid nets most), not the simulated data.",
        ]
    return (
        lines
        + _table(["model", "mm^2 (mean +- sd)", "folds", "epochs", "paper mm^2", "difference"], rows)
        + [""]
        + _image(data, "model_search", "model search")
    )


def _calibration_section(data: dict[str, Any]) -> list[str]:
    labels = [label for label, _ in YAW_SETTINGS]
    rows = []
    for method, m in data["calibration"].items():
        rows.append([f"{method}", *(f"{m['per_setting_px'][label]:.1f}" for label in labels), f"{m['mean_mm']:.2f}"])
        if m["paper_per_setting_px"]:
            rows.append([f"{method}, paper", *(f"{m['paper_per_setting_px'][label]:.1f}" for label in labels), f"{m['paper_mean_mm']:.2f}"])
            rows.append(
                [
                    f"{method}, difference",
                    *(_percent(m["per_setting_px"][label], m["paper_per_setting_px"][label]) for label in labels),
                    _percent(m["mean_mm"], m["paper_mean_mm"]),
                ]
            )
    lines = [
        "## Calibration error (the paper's table)",
        "",
        f"Mean error over the 35 circles, in pixels of the left image (1 mm is about {paper.PX_PER_MM} px), for each yaw setting; "
        "last column the mean over all settings in mm. Touched as the paper's runs were (`dvrk-gym evaluate --protocol paper`): "
        "the rigid body's predictions lifted 4 to 9 mm, and clipped in three settings, as the authors' records show; "
        "the networks' sent as they are.",
        "",
    ]
    lines += _table(["method", *labels, "mean mm"], rows) + [""]
    moves = [
        [
            method,
            f"{m['robot_moves']:,}",
            f"{m['mean_mm']:.2f}",
            f"{m['paper_mean_mm']:.2f}" if m["paper_mean_mm"] else "",
            _percent(m["mean_mm"], m["paper_mean_mm"]),
        ]
        for method, m in data["calibration"].items()
    ]
    lines += _table(["method", "robot moves", "sim mm", "paper mm", "difference"], moves) + [""]
    return lines + _image(data, "calibration_error_maps", "per-circle error maps")


def _debridement_section(data: dict[str, Any]) -> list[str]:
    cells = data["debridement"]
    if not cells:
        return []
    rows = []
    n = paper.DEBRIDEMENT_PICKS_PER_CELL
    for cell in cells:
        reference = cell["paper"]
        picks = max(cell["picks"], 1)
        sim = f"{cell['success']}/{cell['picks']} ({100 * cell['success'] / picks:.0f}%)"
        if unpicked := unpicked_note(cell):  # cells of runs before the count have neither key
            sim += f"; {unpicked}"
        paper_text = f"{reference['success']}/{n} ({100 * reference['success'] / n:.0f}%)" if reference else "-"
        difference = f"{100 * (cell['success'] / picks - reference['success'] / n):+.0f} points" if reference else "-"
        outcomes = f"A {cell['A']}, B {cell['B']}, C {cell['C']}"
        paper_outcomes = f"A {reference['A']}, B {reference['B']}, C {reference['C']}" if reference else "-"
        rows.append(
            [
                cell["fragment"].replace("_", " "),
                cell["method"],
                sim,
                paper_text,
                difference,
                outcomes,
                paper_outcomes,
                f"{cell['time_per_fragment_s']:.2f}",
            ]
        )
    low, high = data["paper_time_per_fragment_s"]
    lines = [
        "## Debridement",
        "",
        f"Each cell: {cells[0]['trials']} trials x {data['settings']['profile']['debridement_picks']} fragments "
        f"(the paper: {paper.DEBRIDEMENT_TRIALS} x {paper.FRAGMENTS_PER_TRIAL}). "
        "Outcomes: A missed (calibration), B slipped though the grip was placed well, C a raisin pulled out by one tip. "
        "A fragment carried off the paper by another's pick has no pick of its own, so a cell can count fewer picks than fragments. "
        f"Seconds per fragment are simulated time (the paper: {low}-{high} s). Rows marked (RL) aim the picks with "
        "the RL agent trained on GridTouch-v0 below, fed the same target as the calibrators (the paper has no such row).",
        "",
    ]
    lines += _table(["fragment", "method", "success", "paper", "difference", "failures", "paper failures", "s/fragment"], rows) + [""]
    phases = list(data["debridement_paper_phase_s"])
    phase_rows = [[f"{c['fragment'].replace('_', ' ')}, {c['method']}", *(f"{c['phase_s'][p]:.2f}" for p in phases)] for c in cells]
    phase_rows.append(["paper (frames / 25 fps)", *(f"{data['debridement_paper_phase_s'][p]:.2f}" for p in phases)])
    lines += ["Time per phase of a pick, seconds:", ""] + _table(["cell", *(p.replace("_", " ") for p in phases)], phase_rows) + [""]
    for cell in cells:
        lines += _image(data, Path(cell["figure"]).stem, f"outcomes, {cell['method']}, {cell['fragment']}")
    return lines


def _rl_section(data: dict[str, Any]) -> list[str]:
    if not data["rl"]:
        return []
    rows = [[method, f"{m['robot_moves']:,}", f"{m['mean_mm']:.2f}", f"{m['mean_px']:.1f}"] for method, m in data["calibration"].items()]
    rows += [[agent["label"], f"{agent['env_steps']:,}", f"{agent['mean_mm']:.2f}", f"{agent['mean_px']:.1f}"] for agent in data["rl"]]
    labels = [label for label, _ in YAW_SETTINGS]
    per_yaw = [[agent["label"], *(f"{agent['summary'][label]['pixel']['mean']:.1f}" for label in labels)] for agent in data["rl"]]
    lines = [
        "## Reinforcement-learning baseline",
        "",
        "Agents trained on GridTouch-v0 (one touch per episode, rewarded by the touch's distance from the circle), "
        "then benchmarked on the calibrators' circles (35 circles x 6 yaw settings, same seeds; their commands sent as they are, "
        "where the rigid body's are lifted as the authors' runs were). The paper has no RL baseline.",
        "",
    ]
    lines += _table(["method", "robot moves", "mean mm", "mean px"], rows) + ["", "Per yaw setting, pixels:", ""]
    lines += _table(["agent", *labels], per_yaw) + [""]
    rates = ", ".join(f"{a['label']} {a['steps_per_second']:.1f}" for a in data["rl"])
    lines += [f"Training speed (env steps/s with the gradient updates): {rates}.", ""]
    return lines + _image(data, "learning_curves", "learning curves")
