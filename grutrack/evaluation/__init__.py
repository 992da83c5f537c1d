"""Evaluation: official nuScenes and AV2 evaluators, a fast exact AMOTA evaluator, metric files."""
