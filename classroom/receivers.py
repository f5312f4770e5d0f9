"""What the classroom hears from the rest of robotide (filled in by classroom.checking)."""
