"""mdaug.inference (see the issues for what it will hold)."""
