/* ProcessPrng, the one function Rust's standard library imports from
 * bcryptprimitives.dll, for Wine releases that lack that DLL (Debian 12's
 * Wine 8.0; Wine added it later). Windows 10 and later ship it as a system
 * DLL, so the FMU binary's import is right for its users; this stand-in only
 * lets tests/test_windows_binaries.py run the DLL under such a Wine. It is
 * placed beside the test importer, never in an FMU, and only when the Wine
 * prefix has no bcryptprimitives.dll of its own.
 *
 * Built with x86_64-w64-mingw32-gcc -shared ... -lbcrypt. */

#include <windows.h>
#include <bcrypt.h>

__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T size);

/* Fills `data` with `size` bytes from the system's preferred generator; like
 * the real one it cannot fail (it aborts the process instead). */
BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T size) {
    while (size > 0) {
        ULONG chunk = size > 0x40000000u ? 0x40000000u : (ULONG)size;
        if (!BCRYPT_SUCCESS(
                BCryptGenRandom(NULL, data, chunk, BCRYPT_USE_SYSTEM_PREFERRED_RNG))) {
            ExitProcess(0xC0000001u);
        }
        data += chunk;
        size -= chunk;
    }
    return TRUE;
}
