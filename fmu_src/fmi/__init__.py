"""What the pythonfmu slaves share: the base slave with its FMI phase rules, and the FMU-state blob."""
