// The translation unit that carries Catch2's precompiled header (tests/CMakeLists.txt,
// ds1928_catch_pch): the test programs reuse the header compiled here instead of parsing it again.
