# grutrack workflow: detections -> GRU-KF training -> tracking -> official submissions -> official evaluation
# -> reports that put the paper's tables beside the reproduced numbers. See README.md, "The workflow".
#
#   snakemake --cores 2 reports/demo_val.md        # the embedded SYNTHETIC demo, no download
#   snakemake -n reports/nusc_val.md               # what would run (dry run)
#
# The config (workflow/config/config.yaml, overridable with --config / --configfile) is validated against
# workflow/schemas/config.schema.yaml before any rule runs; so are the paper's numbers (paper.yaml).

import os
import sys
from pathlib import Path

import yaml
from snakemake.utils import min_version, update_config, validate

from grutrack.errors import ConfigError
from grutrack.pipeline import spec as S

min_version("9.0")

configfile: os.path.join(workflow.basedir, "workflow/config/config.yaml")
# --config values arrive with every nested scalar as a string ('12', '1.2', 'null'): type them as YAML would
_CLI_CONFIG = S.typed_cli_config(workflow.config_settings.config)
update_config(config, _CLI_CONFIG)
try:
    S.validate_config(config, os.path.join(workflow.basedir, "workflow/schemas/config.schema.yaml"),
                      [(f, yaml.safe_load(open(f))) for f in workflow.overwrite_configfiles], _CLI_CONFIG)
except ConfigError as exc:  # a user's error: one line naming the key, exit status 2 (as dataset_input's)
    print(exc, file=sys.stderr)
    raise SystemExit(2)

include: "workflow/rules/common.smk"
include: "workflow/rules/data.smk"
include: "workflow/rules/detections.smk"
include: "workflow/rules/train.smk"
include: "workflow/rules/track.smk"
include: "workflow/rules/submit.smk"
include: "workflow/rules/evaluate.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input: "reports/demo_val.md"
