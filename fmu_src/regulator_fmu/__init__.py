"""The AdaptiveVelocityRegulator pythonfmu slave, thin over ``fmu_src.core``."""
