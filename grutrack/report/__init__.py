"""Reports: the paper's tables (``workflow/config/paper.yaml``) beside reproduced numbers read from metrics
JSONs (never recomputed), figures as PNG, and the paper-vs-reproduced check. One module per report kind."""

#: report kind -> module with ``build(inputs) -> str``
KINDS = {"demo": "grutrack.report.demo", "nusc_val": "grutrack.report.nusc_val",
         "nusc_test": "grutrack.report.nusc_test", "av2_val": "grutrack.report.av2_val",
         "semi_supervised": "grutrack.report.semi_supervised"}
