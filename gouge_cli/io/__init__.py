"""Files: the run file (run.h5), checkpoints, run directories, provenance, self-description."""
