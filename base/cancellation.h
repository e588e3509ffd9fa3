// A request, process-wide, that long work stop early: Ctrl-C in a Python
// session, where the interpreter must get control back and carry on, rather
// than the process dying of the signal (base/interrupt_cleanup.h).
//
// Long work polls it where it reports progress (base/progress.h): there it
// throws, and the error unwinds the work as any other failure would, removing
// its temporaries and unfinished outputs on the way.
#pragma once

namespace octocosm {

void RequestCancellation();
void ClearCancellation();
bool CancellationRequested();
// Throws Error kIo "interrupted" when cancellation is requested.
void ThrowIfCancelled();

}  // namespace octocosm
