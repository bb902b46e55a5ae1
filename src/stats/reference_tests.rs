//! Agreement with scipy on the committed fixture (filled in below).
