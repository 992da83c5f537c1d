"""Dataset adapters (nuScenes, AV2, the synthetic demo) and detection sources, converted at the edge into
the canonical scenes of :mod:`grutrack.data.scene`."""
