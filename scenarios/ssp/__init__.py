"""The SSP system: export a scenario as an SSP, check SSP files against the standard, and run them in other masters."""
