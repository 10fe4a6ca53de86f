"""The regulator's pure core: numpy and the standard library only (it travels inside the FMUs)."""
