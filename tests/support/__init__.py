"""What the tests share: built FMUs, FMI drivers and C hosts, reference models, paths."""
