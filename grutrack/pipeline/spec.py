"""The workflow config (``workflow/config/config.yaml``, already checked against its JSON schema): the
cross-references a schema cannot express, the dataroot check of a real dataset, and where each stage writes
its files. Every error is a :class:`ConfigError` that names the config key and what to put there.

Snakemake parses the Snakefile before it knows the requested targets, so dataroots are checked by the input
functions of the rules that read a dataset: while the DAG is built, before any rule runs, and only for the
datasets the requested targets need (the demo target needs none).
"""

from __future__ import annotations

from pathlib import Path

from grutrack.errors import ConfigError


def report_kind(kind: str):
    """The :class:`grutrack.report.ReportKind` of a config report kind (what its rule gives it)."""
    from grutrack.report import KINDS

    return KINDS[kind]


# ------------------------------------------------------------------------------------------------------------
# command-line values and the schema check
# ------------------------------------------------------------------------------------------------------------


def typed_cli_config(cli: dict) -> dict:
    """Snakemake's ``--config key=value`` with the scalars of its values typed as YAML types them.

    Snakemake reads a value such as ``{epochs: 12}`` or ``{car: 1.2}`` with YAML's BaseLoader, so every
    nested scalar arrives as a string (``'12'``, ``'1.2'``, ``'null'``); the schema then refuses it. Here a
    string that spells a YAML null, boolean (true/false) or number (``12``, ``1.2``, ``1e-5``) becomes that
    value; every other string stays a string. Only the ``--config`` values are typed, never a config file's.
    """

    def typed(v):
        if isinstance(v, dict):
            return {k: typed(x) for k, x in v.items()}
        if isinstance(v, list):
            return [typed(x) for x in v]
        if not isinstance(v, str):
            return v
        t = v.strip()
        if t in ("null", "Null", "NULL", "~"):
            return None
        if t.lower() in ("true", "false"):
            return t.lower() == "true"
        try:
            return int(t) if t.lstrip("+-").isdigit() else float(t) if _looks_numeric(t) else v
        except ValueError:
            return v

    return typed(cli or {})


def _looks_numeric(t: str) -> bool:
    import re

    return re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", t) is not None


def validate_config(cfg: dict, schema_path: str | Path, files: list, cli: dict | None = None) -> None:
    """Check ``cfg`` against the JSON schema at ``schema_path``; the first error is one :class:`ConfigError`
    line naming the key, its value, what the schema expects and where the value came from (a ``--configfile``
    of ``files`` (path, loaded dict), ``--config``, or the shipped config)."""
    import jsonschema
    import yaml

    schema = with_registered_kinds(yaml.safe_load(Path(schema_path).read_text()))
    errors = list(jsonschema.validators.validator_for(schema)(schema).iter_errors(cfg))
    if not errors:
        return
    err = _meant_branch(jsonschema.exceptions.best_match(errors))
    path = list(err.absolute_path)
    if err.validator == "additionalProperties" and isinstance(err.instance, dict):
        extra = sorted(set(err.instance) - set(err.schema.get("properties", {})))
        path += extra[:1]
    key = ".".join(str(p) for p in path) or "<top level>"
    origin = "workflow/config/config.yaml"
    if _has_path(cli or {}, path):
        origin = "--config"
    else:
        for fname, content in reversed(files):
            if _has_path(content, path):
                origin = f"--configfile {fname}"
                break
    raise ConfigError(f"config key {key} (from {origin}): {err.message}")


def _meant_branch(err):
    """For a value that matches none of a ``oneOf`` / ``anyOf`` (e.g. a training entry, which is either
    ``{pretrained: ...}`` or a training), the error inside the branch the value was meant for: the branch with
    the fewest missing required keys, then the fewest errors; so a misspelt key of a training is named, not the
    whole entry."""
    import jsonschema

    while err.validator in ("oneOf", "anyOf") and err.context:
        branches: dict = {}
        for sub in err.context:
            branches.setdefault(sub.relative_schema_path[0], []).append(sub)
        meant = min(branches.values(), key=lambda es: (sum(e.validator == "required" for e in es), len(es)))
        err = jsonschema.exceptions.best_match(meant)
    return err


def with_registered_kinds(schema: dict) -> dict:
    """The workflow config schema with the kinds the registries define: a ``datasets`` entry takes one of the
    kinds of :func:`grutrack.datasets.config_kinds` and, for each, that kind's schema
    (``$defs/<kind>_dataset``); a ``reports`` entry one of :data:`grutrack.report.KINDS`."""
    from grutrack.datasets import config_kinds
    from grutrack.report import KINDS

    report = schema["properties"]["reports"]["additionalProperties"]
    report["properties"]["kind"] = {"enum": list(KINDS)}

    kinds = config_kinds()
    entry = schema["properties"]["datasets"]["additionalProperties"]
    entry["properties"] = {**entry.get("properties", {}), "kind": {"enum": sorted(kinds)}}
    entry["allOf"] = [
        {"if": {"properties": {"kind": {"const": k}}}, "then": {"$ref": f"#/$defs/{k}_dataset"}} for k in sorted(kinds)
    ]
    schema["$defs"].update({f"{k}_dataset": sub for k, (_, sub) in kinds.items()})
    return schema


def _has_path(d, path: list) -> bool:
    """Whether the nested dict ``d`` sets the key ``path`` (or a parent of it that is not a dict)."""
    for p in path:
        if not isinstance(d, dict) or p not in d:
            return False
        d = d[p]
    return True


# ------------------------------------------------------------------------------------------------------------
# cross-references
# ------------------------------------------------------------------------------------------------------------


def check_config(cfg: dict, paper: dict, registry: dict) -> None:
    """Check every name the config refers to; resolve tracker presets and training configs with overrides."""
    from grutrack.pipeline.presets import resolve_tracker, resolve_training

    for name, preset in cfg["tracker_presets"].items():
        _resolved(f"tracker_presets.{name}", lambda: resolve_tracker(preset["base"], preset["overrides"]))
    for name, tr in cfg["trainings"].items():
        key = f"trainings.{name}"
        if "pretrained" in tr:
            _check_pretrained(key, tr["pretrained"])
            continue
        _need(cfg["datasets"], tr["dataset"], f"{key}.dataset", "datasets")
        _need(cfg["detectors"], tr["detector"], f"{key}.detector", "detectors")
        ds = dataset_class(cfg, tr["dataset"])
        if tr["validation"] and not ds.validates_training:
            raise ConfigError(
                f"config key {key}.validation: validation AMOTA during training is scored on "
                f"nuScenes-format data, not on '{tr['dataset']}' ({ds.name}); set it to null"
            )
        splits = [tr["split"]] + ([tr["validation"]["split"]] if tr["validation"] else [])
        for split in splits:
            _detector_covers(cfg, registry, tr["detector"], split, f"{key}.detector")
        _resolved(key, lambda: resolve_training(tr["config"], tr["overrides"]))
    for name, exp in cfg["experiments"].items():
        _check_experiment(cfg, registry, name, exp)
    for name, rep in cfg["reports"].items():
        _check_report(cfg, paper, name, rep)


def _check_pretrained(key: str, name: str) -> None:
    """A ``{pretrained: name}`` training must name a network shipped in the package, with its files present."""
    from grutrack.training.pretrained import FILES, PRETRAINED, pretrained_dir

    if name not in PRETRAINED:
        raise ConfigError(
            f"config key {key}.pretrained: '{name}' is not a shipped pretrained network "
            f"(choose {', '.join(PRETRAINED)})"
        )
    missing = [f for f in FILES if not (pretrained_dir(name) / f).is_file()]
    if missing:
        raise ConfigError(
            f"config key {key}.pretrained: {pretrained_dir(name)} lacks {', '.join(missing)} "
            f"(a checkout without its large files? re-run bash scripts/pretrain_grukf.sh)"
        )


def _resolved(key: str, fn) -> None:
    """Run a resolver; its error is prefixed with the config key."""
    try:
        fn()
    except ConfigError as exc:
        raise ConfigError(f"config key {key}: {exc}") from exc


def _need(section: dict, name, key: str, section_name: str) -> None:
    if name not in section:
        raise ConfigError(
            f"config key {key}: '{name}' is not defined under {section_name} (defined: {', '.join(section) or 'none'})"
        )


def _detector_covers(cfg: dict, registry: dict, det: str, split: str, key: str) -> None:
    """A simulated detector needs a seed for the split, a registry detector a source."""
    d = cfg["detectors"][det]
    if d["kind"] == "simulated" and split not in d["seeds"]:
        raise ConfigError(
            f"config key detectors.{det}.seeds has no seed for split '{split}' (used by {key}); add e.g. {split}: 1"
        )
    if d["kind"] == "registry":
        if split not in d["sources"]:
            raise ConfigError(
                f"config key detectors.{det}.sources has no source for split '{split}' (used by "
                f"{key}); add {split}: <name in grutrack/configs/detections.yaml>"
            )
        _need(registry, d["sources"][split], f"detectors.{det}.sources.{split}", "grutrack/configs/detections.yaml")
    if d["kind"] == "local" and split not in d["files"]:
        raise ConfigError(
            f"config key detectors.{det}.files has no file for split '{split}' (used by {key}); add "
            f"{split}: <path to the detection file>"
        )


def _check_experiment(cfg: dict, registry: dict, name: str, exp: dict) -> None:
    key = f"experiments.{name}"
    _need(cfg["datasets"], exp["dataset"], f"{key}.dataset", "datasets")
    kind = cfg["datasets"][exp["dataset"]]["kind"]
    for det in exp["detectors"]:
        _need(cfg["detectors"], det, f"{key}.detectors", "detectors")
        _detector_covers(cfg, registry, det, exp["split"], f"{key}.detectors")
    for run_name, run in exp["runs"].items():
        rkey = f"{key}.runs.{run_name}"
        _need(cfg["tracker_presets"], run["preset"], f"{rkey}.preset", "tracker_presets")
        if (run["tracker"] == "grukf") != (run["training"] is not None):
            raise ConfigError(f"config key {rkey}.training: a grukf run needs a training, other trackers none")
        if run["training"] is not None:
            _need(cfg["trainings"], run["training"], f"{rkey}.training", "trainings")
    ds = dataset_class(cfg, exp["dataset"])
    evaluators = (*ds.evaluators, "none")
    if exp["evaluator"] not in evaluators:
        raise ConfigError(
            f"config key {key}.evaluator: '{exp['evaluator']}' is not available for a {kind} "
            f"dataset (choose {', '.join(evaluators)})"
        )
    cc = exp.get("cross_check")
    if cc is not None:
        _need(exp["runs"], cc["run"], f"{key}.cross_check.run", f"{key}.runs")
        if exp["evaluator"] != "fast" or "devkit" not in ds.evaluators:
            raise ConfigError(
                f"config key {key}.cross_check: the cross-check compares the fast evaluator with the "
                f"devkit on nuScenes-format data; experiment '{name}' is evaluated with "
                f"'{exp['evaluator']}' on {kind} (set evaluator: fast, or cross_check: null)"
            )
    lb = exp["leaderboard_run"]
    if lb is not None:
        _need(exp["runs"], lb, f"{key}.leaderboard_run", f"{key}.runs")
        if not ds.leaderboard_zip:
            raise ConfigError(
                f"config key {key}.leaderboard_run: leaderboard zips are built for nuScenes-format "
                f"datasets, not {kind}; set it to null"
            )


def _check_report(cfg: dict, paper: dict, name: str, rep: dict) -> None:
    key = f"reports.{name}"
    kind = report_kind(rep["kind"])
    for role in kind.training_roles:
        if role not in rep["trainings"]:
            raise ConfigError(f"config key {key}.trainings needs '{role}': <training name>")
        tr = rep["trainings"][role]
        _need(cfg["trainings"], tr, f"{key}.trainings.{role}", "trainings")
        if cfg["trainings"][tr].get("validation") is None and not is_pretrained(cfg, tr):
            raise ConfigError(
                f"config key trainings.{tr}.validation must be set (the figure plots validation AMOTA against step)"
            )
    if not kind.datasets or (rep["experiment"] is None and kind.optional_experiment):
        return
    if rep["experiment"] is None:
        raise ConfigError(f"config key {key}.experiment: a {rep['kind']} report needs an experiment")
    _need(cfg["experiments"], rep["experiment"], f"{key}.experiment", "experiments")
    exp = cfg["experiments"][rep["experiment"]]
    ds_kind = cfg["datasets"][exp["dataset"]]["kind"]
    if ds_kind not in kind.datasets:
        raise ConfigError(
            f"config key {key}.experiment: a {rep['kind']} report needs a "
            f"{' or '.join(kind.datasets)} experiment, '{rep['experiment']}' is {ds_kind}"
        )
    if "zips" in kind.reads and exp["leaderboard_run"] is None:
        raise ConfigError(
            f"config key experiments.{rep['experiment']}.leaderboard_run must name the run whose zips "
            f"the {name} report shows"
        )
    if "runs" in kind.reads and exp["evaluator"] == "none":
        raise ConfigError(
            f"config key {key}.experiment: a {rep['kind']} report needs metrics, but experiment "
            f"'{rep['experiment']}' has evaluator none"
        )
    for table, rows in rep["tables"].items():
        _need(paper["tables"], table, f"{key}.tables", "the paper tables (paper.yaml)")
        for row, run in rows.items():
            _need(paper["tables"][table]["rows"], row, f"{key}.tables.{table}", f"paper.yaml tables.{table}.rows")
            _need(exp["runs"], run, f"{key}.tables.{table}.{row}", f"experiments.{rep['experiment']}.runs")
    for table, rows in rep.get("extra_rows", {}).items():
        _need(paper["tables"], table, f"{key}.extra_rows", "the paper tables (paper.yaml)")
        for row, run in rows.items():
            if row in paper["tables"][table]["rows"]:
                raise ConfigError(
                    f"config key {key}.extra_rows.{table}.{row}: '{row}' is a row of the paper's table "
                    f"{table}; list it under {key}.tables.{table}"
                )
            _need(exp["runs"], run, f"{key}.extra_rows.{table}.{row}", f"experiments.{rep['experiment']}.runs")


# ------------------------------------------------------------------------------------------------------------
# datasets and dataroots
# ------------------------------------------------------------------------------------------------------------


def version_for(cfg: dict, dataset: str, split: str) -> str | None:
    """The dataset version a split lives in, as the dataset class reads its config entry (nuScenes test lives
    in test_version; AV2 has none)."""
    return dataset_class(cfg, dataset).config_version(cfg["datasets"][dataset], split)


def require_dataroot(cfg: dict, dataset: str, split: str | None = None) -> str:
    """The dataroot of a real dataset, checked to exist; the error names the config key and what to put."""
    ds = cfg["datasets"][dataset]
    key = f"datasets.{dataset}.dataroot"
    if ds["kind"] == "demo":
        return ds["dataroot"]
    version = version_for(cfg, dataset, split or "val") or ""
    cls = dataset_class(cfg, dataset)
    hint = cls.dataroot_hint.format(version=version, split=split or "<split>")
    root = ds["dataroot"]
    if not root:
        raise ConfigError(
            f"config key {key} is not set: put there {hint} (edit workflow/config/config.yaml or "
            f"pass --config 'datasets={{{dataset}: {{dataroot: /path/to/it}}}}')"
        )
    need = Path(root) / cls.dataroot_folder.format(version=version, split=split or "")
    if not need.is_dir():
        raise ConfigError(f"config key {key} = {root}: {need} does not exist; it must be {hint}")
    return root


# ------------------------------------------------------------------------------------------------------------
# file layout
# ------------------------------------------------------------------------------------------------------------


def dataset_kind(cfg: dict, dataset: str) -> str:
    """The config kind of a dataset entry (one a dataset class declares in its ``config_kinds``)."""
    return cfg["datasets"][dataset]["kind"]


def dataset_name(cfg: dict, dataset: str) -> str:
    """The :mod:`grutrack.datasets` name (``--dataset``) of a config dataset: the class that declares its kind
    (the demo is nuScenes-format)."""
    from grutrack.datasets import config_kinds

    return config_kinds()[dataset_kind(cfg, dataset)][0]


def dataset_class(cfg: dict, dataset: str) -> type:
    """The :mod:`grutrack.datasets` class of a config dataset."""
    from grutrack.datasets import dataset_class as cls

    return cls(dataset_name(cfg, dataset))


def evaluation_threads(cfg: dict, dataset: str) -> int:
    """Threads an evaluation job of the dataset asks for (Snakemake caps them at --cores): several when its
    evaluator runs worker processes, else one."""
    return 8 if dataset_class(cfg, dataset).parallel_evaluation else 1


def dataset_args(cfg: dict, dataset: str, split: str) -> str:
    """The command-line arguments that name a config dataset and split for any ``grutrack`` command
    (``--dataset``, ``--dataroot``, ``--version`` or ``--rate``, ``--split``), shell-quoted."""
    import shlex

    ds = cfg["datasets"][dataset]
    cls = dataset_class(cfg, dataset)
    args = ["--dataset", cls.name, "--dataroot", str(ds["dataroot"]), "--split", split]
    version = cls.config_version(ds, split)
    if version:
        args += ["--version", version]
    args += cls.config_options(ds)
    return " ".join(shlex.quote(a) for a in args)


def demo_sentinel(cfg: dict, dataset: str) -> str:
    """The demo dataset's folder, which the demo-data rule writes and later rules depend on."""
    return cfg["datasets"][dataset]["dataroot"]


def detections_file(cfg: dict, dataset: str, split: str, detector: str) -> str:
    """Detections of one split, simulated or converted from a registry source."""
    how = "simulated" if cfg["detectors"][detector]["kind"] == "simulated" else "converted"
    return f"detections/{how}/{dataset}/{split}/{detector}{dataset_class(cfg, dataset).detections_suffix}"


def raw_source_file(registry: dict, source: str) -> str:
    """Where a registry source is downloaded to (or put by hand)."""
    return f"detections/raw/{source}/{registry[source].filename}"


def tracks_file(cfg: dict, experiment: str, detector: str, run: str) -> str:
    """The tracker's output of one run."""
    suffix = dataset_class(cfg, cfg["experiments"][experiment]["dataset"]).submission_suffix
    return f"results/{experiment}/{detector}/{run}/tracks{suffix}"


def submission_file(cfg: dict, experiment: str, detector: str, run: str) -> str:
    """The validated submission of one run (its manifest sits beside it)."""
    suffix = dataset_class(cfg, cfg["experiments"][experiment]["dataset"]).submission_suffix
    return f"submissions/{experiment}/{detector}/{run}{suffix}"


def metrics_file(experiment: str, detector: str, run: str) -> str:
    """The metrics JSON of one run."""
    return f"reports/metrics/{experiment}/{detector}/{run}.json"


def cross_check_file(experiment: str, detector: str, run: str) -> str:
    """The devkit-vs-fast cross-check JSON of one run (rule cross_check)."""
    return f"reports/metrics/{experiment}/{detector}/{run}.crosscheck.json"


def is_pretrained(cfg: dict, training: str) -> bool:
    """Whether training entry ``training`` is a shipped pretrained network (``{pretrained: name}``)."""
    return "pretrained" in cfg["trainings"][training]


def trained_names(cfg: dict) -> list[str]:
    """The training entries the workflow trains (stage train); shipped pretrained networks are not among them."""
    return [name for name in cfg["trainings"] if not is_pretrained(cfg, name)]


def training_dir(cfg: dict, training: str) -> str:
    """The folder of a training's model.pt, train_log.csv, training.yaml and validation.json: checkpoints/<name>
    for a workflow training, the package's grutrack/pretrained/<name> for a shipped one."""
    if is_pretrained(cfg, training):
        from grutrack.training.pretrained import pretrained_dir

        return str(pretrained_dir(cfg["trainings"][training]["pretrained"]))
    return f"checkpoints/{training}"


def checkpoint_file(cfg: dict, training: str) -> str:
    """The model a training entry stands for (see :func:`training_dir`)."""
    return f"{training_dir(cfg, training)}/model.pt"
