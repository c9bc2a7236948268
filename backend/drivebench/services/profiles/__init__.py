"""The device profiles as the API and the pages offer them: summaries, load errors, entry search (views), upload,
store, delete and who uses a profile (store)."""
