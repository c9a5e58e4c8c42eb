"""Planning: a task → transcription → solver → a result record."""
