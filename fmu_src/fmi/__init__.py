"""The FMI layer every FMU of the project shares: the phase rules and the C they generate."""
