"""eddiebot."""
