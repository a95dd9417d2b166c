"""A mission's sound-source array fitted on every float that hears it (`array_fit`), the
block-arrow solve it rests on (`schur`), and the floats as it sees them (`floats`)."""
