"""mdaug.reports: the study (:mod:`.study`), its statistics and verdicts, and its report
(:mod:`.report`) and README section (:mod:`.readme`)."""
