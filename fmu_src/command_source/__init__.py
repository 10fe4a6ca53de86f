"""The CommandSource FMU (C, FMI 2.0 / 3.0): a scenario's command and pushes as outputs, for the SSP."""
