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

from snakemake.utils import min_version, validate

min_version("9.0")

configfile: os.path.join(workflow.basedir, "workflow/config/config.yaml")
validate(config, "workflow/schemas/config.schema.yaml", set_default=False)

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
