"""What people read: figures (:mod:`~arfi.reports.figures`), the verbs' HTML pages
(:mod:`~arfi.reports.html`) and the report of ``arfi diagnose`` (:mod:`~arfi.reports.diagnose`)."""
