"""mdaug.reports: the study and its report, on top of the library.

* the study: :mod:`.study` (its stages, cached by :mod:`.cache`, run by an
  :mod:`.executor`), its training stages (:mod:`.study_training`), its picklable jobs
  (:mod:`.jobs`), its config (:mod:`.config`, checked by :mod:`.validation`) and the
  speed stage (:mod:`.speed`);
* the numbers: :mod:`.statistics` (every classifier scored on the same resamples) and
  :mod:`.verdicts` (every verdict, in one place);
* the words and the page: :mod:`.finding` (the sentences), :mod:`.report` assembling
  the ``page_*`` sections from :mod:`.numbers` and :mod:`.markup`, the figures
  (:mod:`.figures`, :mod:`.figures_speed`, in the :mod:`.style`), and the README's
  results section (:mod:`.readme`).

The training-set strategies it compares are the registry :mod:`mdaug.strategies`.
"""
