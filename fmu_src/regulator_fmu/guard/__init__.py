"""The FMI 2.0 guard of the pythonfmu FMUs: C sources here, built by :mod:`.build_guard`."""
