// Boost.Asio as this project includes it. Boost 1.74's awaitable.hpp uses std::exchange without
// including <utility>, which breaks C++20 builds depending on include order: include Asio
// through this header.
#pragma once

// clang-format off
#include <utility>
#include <boost/asio.hpp>
// clang-format on
