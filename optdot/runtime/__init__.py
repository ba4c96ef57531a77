"""What the machine allows: the up-front memory estimate."""
