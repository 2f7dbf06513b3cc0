"""The simulator keeps no database state: worlds are files, robots live in memory."""
