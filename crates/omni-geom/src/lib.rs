//! Pure geometry: rays, planes, rigid transforms, least-squares fits. No I/O.
