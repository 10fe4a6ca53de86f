"""The CassiePlant pythonfmu slave and its pure core over ``plant`` (the FMU's variables, state and checks)."""
