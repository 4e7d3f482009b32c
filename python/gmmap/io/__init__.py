"""Data in and out: dataset loaders, the simulator and Rerun recordings."""
