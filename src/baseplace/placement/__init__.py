"""Base placement: the OSRM (seed 000), sampling strategies, baselines and the one verification."""
