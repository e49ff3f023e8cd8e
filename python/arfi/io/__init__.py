"""Files in and out: MR-ARFI images and phases (:mod:`~arfi.io.files`), scanner DICOM
(:mod:`~arfi.io.dicom`), beam volumes (:mod:`~arfi.io.volume`) and the synthetic head CT
(:mod:`~arfi.io.phantom`). Nothing here simulates; it reads, writes and makes inputs."""
