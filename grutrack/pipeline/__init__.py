"""Support for the Snakemake workflow (``Snakefile``, ``workflow/``): resolved tracker and training configs,
per-stage code versions, and the workflow config's cross-references, dataroots and file layout."""
