# Stage "report": reports/<name>.md and its figures (PNG) from metrics JSONs, manifests and training logs;
# the paper's numbers (paper.yaml) beside the reproduced ones. Reports never recompute a metric.


def _report(w):
    return config["reports"][w.report]


def _report_runs(rep):
    """(run, metrics JSON, manifest) of the report's experiment, first detector (evaluated experiments)."""
    if "runs" not in S.report_kind(rep["kind"]).reads or not rep["experiment"]:
        return []
    exp_name = rep["experiment"]
    det = config["experiments"][exp_name]["detectors"][0]
    sub = lambda run: S.submission_file(config, exp_name, det, run)
    return [(run, S.metrics_file(exp_name, det, run), re.sub(r"\.(json|pkl)$", ".manifest.json", sub(run)))
            for run in config["experiments"][exp_name]["runs"]]


def _report_trainings(rep):
    """(name, train_log.csv, training.yaml) of the trainings the report shows: its own ``trainings`` map when its
    kind names training roles, else those of its experiment's GRU-KF runs."""
    kind = S.report_kind(rep["kind"])
    if "trainings" not in kind.reads:
        return []
    if kind.training_roles:
        names = rep["trainings"]
    else:
        runs = config["experiments"][rep["experiment"]]["runs"]
        names = {r["training"]: r["training"] for r in runs.values() if r["training"]}
    return [(label, f"{S.training_dir(config, t)}/train_log.csv", f"{S.training_dir(config, t)}/training.yaml")
            for label, t in names.items()]


def _report_renders(rep):
    """(run, render folder) of a report that shows each run's worst scene (experiments with ground truth: not
    nuScenes test)."""
    if "renders" not in S.report_kind(rep["kind"]).reads:
        return []
    exp_name = rep["experiment"]
    det = config["experiments"][exp_name]["detectors"][0]
    return [(run, f"reports/renders/{exp_name}/{det}/{run}") for run in config["experiments"][exp_name]["runs"]]


def _report_zips(rep):
    """(detector, zip, manifest) of a leaderboard report."""
    if "zips" not in S.report_kind(rep["kind"]).reads:
        return []
    name = rep["experiment"]
    exp = config["experiments"][name]
    return [(det, f"submissions/{name}_{det}.zip",
             re.sub(r"\.json$", ".manifest.json", S.submission_file(config, name, det, exp["leaderboard_run"])))
            for det in exp["detectors"]]


def _report_cross_check(rep):
    """(run, cross-check JSON) of the report's experiment when it has a cross_check, else None."""
    if "runs" not in S.report_kind(rep["kind"]).reads or not rep["experiment"]:
        return None
    exp_name = rep["experiment"]
    cc = config["experiments"][exp_name].get("cross_check")
    if not cc:
        return None
    det = config["experiments"][exp_name]["detectors"][0]
    return cc["run"], S.cross_check_file(exp_name, det, cc["run"])


def _report_inputs(w):
    rep = _report(w)
    files = [PAPER_PATH]
    cc = _report_cross_check(rep)
    files += [cc[1]] if cc else []
    for _, metrics, manifest in _report_runs(rep):
        files += [metrics, manifest]
    for _, log_csv, cfg in _report_trainings(rep):
        files += [log_csv, cfg]
    for _, zp, manifest in _report_zips(rep):
        files += [zp, manifest]
    files += [folder for _, folder in _report_renders(rep)]
    return files


def _report_args(w):
    """The report's command-line arguments: every file it reads, and which run reproduces which paper row."""
    rep = _report(w)
    args = [f"--paper {PAPER_PATH}", f"--name {w.report}"]
    if rep["experiment"]:
        exp = config["experiments"][rep["experiment"]]
        det = exp["detectors"][0]
        simulated = ":simulated" if config["detectors"][det]["kind"] == "simulated" else ""
        args.append(f"--experiment {rep['experiment']}:{S.dataset_kind(config, exp['dataset'])}:{exp['split']}:"
                    f"{det}{simulated}")
    args += [f"--run {run}={metrics}" for run, metrics, _ in _report_runs(rep)]
    args += [f"--train-log {label}={log_csv}" for label, log_csv, _ in _report_trainings(rep)]
    kind = S.report_kind(rep["kind"])
    if rep["experiment"] and "trainings" in kind.reads and not kind.training_roles:
        runs = config["experiments"][rep["experiment"]]["runs"]
        args += [f"--run-training {run}={r['training']}" for run, r in runs.items() if r["training"]]
    args += [f"--zip {det}={zp}" for det, zp, _ in _report_zips(rep)]
    args += [f"--render {run}={folder}/counts.json" for run, folder in _report_renders(rep)]
    cc = _report_cross_check(rep)
    args += [f"--cross-check {cc[0]}={cc[1]}"] if cc else []
    args += [f"--row {shlex.quote(f'{table}:{row}={run}')}" for table, rows in rep["tables"].items()
             for row, run in rows.items()]
    args += [f"--extra-row {shlex.quote(f'{table}:{row}={run}')}" for table, rows in rep.get("extra_rows", {}).items()
             for row, run in rows.items()]
    return " ".join(args)


rule render:
    """Bird's-eye frames of a run's worst scene (AV2: log) with its evaluator's own decisions (the reports'
    key-frame strips)."""
    input: unpack(_eval_inputs)
    output: directory("reports/renders/{experiment}/{detector}/{run}")
    params:
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        code=code_version("render"),
    threads: lambda w: S.evaluation_threads(config, experiment(w)["dataset"])
    log: "logs/render/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/render/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} render {params.data} --workers {threads} --submission {input.submission} --worst 1 "
        "--no-animation --out {output} > {log} 2>&1 " + ON_FAIL


rule report:
    input: _report_inputs
    output:
        md="reports/{report}.md",
        figures=directory("reports/figures/{report}"),
    wildcard_constraints:
        report=_alternation(config["reports"]),
    params:
        kind=lambda w: _report(w)["kind"],
        spec=lambda w: jq(_report(w)),
        args=_report_args,
        code=code_version("report"),
    log: "logs/report/{report}.log"
    benchmark: "logs/benchmarks/report/{report}.tsv"
    shell:
        "{GRUTRACK} report {params.kind} {params.args} --out {output.md} --figures {output.figures} "
        "> {log} 2>&1 " + ON_FAIL
