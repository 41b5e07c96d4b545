"""G-code text in, G-code text out: lexer, modal interpreter, path sampling, emitter."""
