"""mdaug.reports (see the issues for what it will hold)."""
