# Shared definitions: the interpreter every rule runs grutrack with, the cross-checked config, the paper's
# numbers, the detection registry, and input functions. Logic lives in grutrack.pipeline (tested there).

import json
import re
import shlex

import yaml

from grutrack.data.registry import load_registry
from grutrack.errors import ConfigError
from grutrack.pipeline import spec as S
from grutrack.pipeline.codever import code_version
from grutrack.report.paper import load_paper

PY = sys.executable                      # the environment's interpreter (the one running snakemake)
GRUTRACK = f"{PY} -m grutrack"
# on failure, show the end of the rule's log on the terminal
ON_FAIL = "|| {{ tail -n 25 {log} >&2; exit 1; }}"

PAPER_PATH = str(Path(workflow.basedir) / config["paper"]) if not os.path.isabs(config["paper"]) else config["paper"]
try:
    PAPER = load_paper(PAPER_PATH)        # the one config loader: schema grutrack/configs/schemas/paper.schema.yaml
    REGISTRY = load_registry()
    S.check_config(config, PAPER, REGISTRY)
except ConfigError as _exc:  # one line naming the file, key or field, exit status 2, before any rule runs
    print(_exc, file=sys.stderr)
    raise SystemExit(2)


def _alternation(names):
    """A wildcard regex matching exactly these names (none: matches nothing)."""
    names = sorted(names)
    return "|".join(re.escape(n) for n in names) if names else "(?!x)x"


wildcard_constraints:
    dataset=_alternation(config["datasets"]),
    detector=_alternation(config["detectors"]),
    training=_alternation(S.trained_names(config)),
    run=_alternation({r for e in config["experiments"].values() for r in e["runs"]}),
    split="[^/]+",
    source="[^/]+",


def dataset_input(dataset, split=None):
    """Input of a rule that reads a dataset: the demo's folder (built by demo_data), nothing for a real dataset,
    whose dataroot is checked here, while the DAG is built and before any rule runs: a missing one stops
    Snakemake with exit status 2 and one line naming the config key and what to put there (an exception raised
    here would reach the user inside Snakemake's InputFunctionException, with a traceback)."""
    try:
        S.require_dataroot(config, dataset, split)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        raise SystemExit(2)
    if S.dataset_kind(config, dataset) == "demo":
        return [S.demo_sentinel(config, dataset)]
    return []


def dataroot(dataset):
    return config["datasets"][dataset]["dataroot"]


def experiment(w):
    return config["experiments"][w.experiment]


def run_of(w):
    return config["experiments"][w.experiment]["runs"][w.run]


def jq(obj):
    """Compact, key-sorted JSON of a config value (a params value and a CLI argument)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))
