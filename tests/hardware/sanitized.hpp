#pragma once
// True in sanitizer builds (MANIP_SANITIZE=ON): the heavy session tests then
// run shortened sessions (a Debug + ASan/UBSan loop cycle costs ~400 us).
#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif
#else
inline constexpr bool kSanitized = false;
#endif
