"""mdaug.classify (see the issues for what it will hold)."""
