"""The FMI layer the FMUs share: the table of FMI phase rules and the C the build generates from
it, the native FMUs' common FMI functions and state-blob framing check, and the pythonfmu slaves'
base slave and FMU-state blob."""
